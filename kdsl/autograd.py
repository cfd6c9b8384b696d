"""``kdsl.autograd``: Jacobians and gradient checks (Warp's ``warp.autograd`` API).

``jacobian`` builds the Jacobian from adjoint launches (one reverse pass per
output element); ``jacobian_fd`` from central finite differences (two forward
evaluations per input element); ``gradcheck`` compares them, and
``gradcheck_tape`` does so for every kernel launch recorded on a ``Tape``.

``function`` is a kernel (with ``dim``, ``inputs`` and ``outputs`` as for
``kdsl.launch``) or a Python function that takes ``inputs`` and returns a kdsl
array or a list of them (launching kernels inside). Only float arrays with
``requires_grad=True`` take part. Jacobians are NumPy float64 matrices keyed by
``(input index, output index)``: ``J[k, j] = d out[k] / d in[j]``, where both arrays
are flattened in row-major order with vector and matrix components last.

Finite differences are as precise as the kernel's arithmetic: the differences are
divided in float64, but a float32 kernel's outputs carry float32 rounding, so the
error of a float32 check is about ``1e-7 * |output| / eps``. Check gradients of
float64 versions of kernels where you can (and use a smaller ``eps`` there);
otherwise keep ``eps`` near 1e-3..1e-4 and loose tolerances.

Plotting options of Warp (``plot_jacobians``, ``plot_*_error``) are not provided.
"""

from __future__ import annotations

import inspect
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from kdsl.errors import KdslError
from kdsl.ir import types as T
from kdsl.runtime import cuda_memory as mem
from kdsl.runtime.array import array
from kdsl.runtime.launch import launch
from kdsl.runtime.modules import backward_enabled
from kdsl.runtime.tape import LaunchRecord, Tape

__all__ = [
    "GradcheckError",
    "gradcheck",
    "gradcheck_tape",
    "jacobian",
    "jacobian_fd",
]

Jacobians = dict[tuple[int, int], np.ndarray]


class GradcheckError(KdslError, ValueError):
    """Autodiff and finite-difference gradients differ (or are NaN).

    Also a ``ValueError``, which is what Warp's ``gradcheck`` raises.
    """


def _is_kernel(f: Any) -> bool:
    return getattr(f, "__kdsl_kernel__", False) is True


def _differentiable(a: Any) -> bool:
    return (
        isinstance(a, array)
        and a.requires_grad
        and a.grad is not None
        and a._t is not None
        and T.elem_type(a._t).is_float
    )


def _host(a: array) -> np.ndarray:
    """The data of ``a`` on the host, flat, as float64 (a copy)."""
    return np.array(a.numpy(), dtype=np.float64).reshape(-1)


def _set_flat(a: array, j: int, value: float) -> None:
    """Set scalar ``j`` of ``a`` in row-major order (components included)."""
    buf = a._buf
    idx = tuple(int(i) for i in np.unravel_index(j, buf.shape))
    with mem.scope(a.device):
        buf[idx] = value


def _assign_host(a: array, data: np.ndarray) -> None:
    with mem.scope(a.device):
        if a.device.is_cuda:
            a._buf[...] = mem.cupy().asarray(data)
        else:
            a._buf[...] = data


def _unique_arrays(values: Sequence[Any]) -> list[array]:
    seen: dict[int, array] = {}
    for v in values:
        if isinstance(v, array):
            seen.setdefault(id(v), v)
    return list(seen.values())


class _Snapshot:
    """Host copies of some arrays' data, to put back with ``restore()``."""

    def __init__(self, arrays: Sequence[array]) -> None:
        self.saved = [(a, a.numpy().copy()) for a in _unique_arrays(arrays)]

    def restore(self) -> None:
        for a, data in self.saved:
            _assign_host(a, data)


@dataclass
class _Problem:
    """A kernel launch or a Python function, with its differentiable arguments."""

    function: Any
    dim: Any
    inputs: list
    outputs: list
    input_labels: list[str]
    output_labels: list[str]
    device: Any = None
    backend: Any = None
    max_blocks: int = 0
    block_dim: int = 256
    pairs: list[tuple[int, int]] = field(default_factory=list)

    @property
    def is_kernel(self) -> bool:
        return _is_kernel(self.function)

    @property
    def name(self) -> str:
        return getattr(self.function, "name", None) or getattr(self.function, "__name__", "?")

    def run(self) -> list:
        """Evaluate once (kernels: on the given outputs); the outputs, as a list."""
        if self.is_kernel:
            launch(
                self.function, self.dim, self.inputs, self.outputs, device=self.device,
                max_blocks=self.max_blocks, block_dim=self.block_dim, backend=self.backend,
                record_tape=False,
            )  # fmt: skip
            return self.outputs
        return _as_outputs(self.function(*self.inputs), self.name)


def _as_outputs(result: Any, name: str) -> list:
    if isinstance(result, array):
        return [result]
    if isinstance(result, list | tuple) and all(isinstance(r, array) for r in result) and result:
        return list(result)
    raise KdslError(
        f"function '{name}' must return a kdsl array or a list of them to be differentiated, "
        f"got {type(result).__name__}"
    )


def _resolve_index(key: str | int, labels: list[str], what: str) -> int:
    if isinstance(key, int) and not isinstance(key, bool):
        if 0 <= key < len(labels):
            return key
    elif key in labels:
        return labels.index(key)
    raise KdslError(f"input_output_mask: no {what} {key!r}; the {what}s are {labels}")


def _problem(
    function: Any,
    dim: Any,
    inputs: Sequence[Any] | None,
    outputs: Sequence[Any] | None,
    mask: Sequence[tuple[str | int, str | int]] | None,
    device: Any,
    backend: Any,
    max_blocks: int,
    block_dim: int,
    need_backward: bool,
) -> _Problem:
    """Check the arguments and describe what to differentiate (runs nothing)."""
    if inputs is None or isinstance(inputs, array) or not isinstance(inputs, Sequence):
        raise KdslError("inputs must be a list of the function's arguments")
    inputs = list(inputs)
    if _is_kernel(function):
        if dim is None:
            raise KdslError(f"kernel '{function.name}': dim is required to differentiate a kernel")
        if not outputs:
            raise KdslError(f"kernel '{function.name}': give its output arrays as outputs=[...]")
        outputs = list(outputs)
        names = list(function.arg_names)
        if len(inputs) + len(outputs) != len(names):
            raise KdslError(
                f"kernel '{function.name}' takes {len(names)} arguments ({', '.join(names)}) "
                f"but {len(inputs)} inputs and {len(outputs)} outputs were given"
            )
        if need_backward and not backward_enabled(function):
            raise KdslError(
                f"kernel '{function.name}' was declared with enable_backward=False: it has no "
                "adjoint to compute a Jacobian from"
            )
        if device is None:
            device = next((a.device for a in inputs + outputs if isinstance(a, array)), None)
        labels_in, labels_out = names[: len(inputs)], names[len(inputs) :]
    elif callable(function):
        outputs = []
        labels_in = list(inspect.signature(function).parameters)[: len(inputs)]
        labels_in += [f"input_{i}" for i in range(len(labels_in), len(inputs))]
        labels_out = []
    else:
        raise KdslError(
            f"expected a kdsl kernel or a Python function, got {type(function).__name__}"
        )
    return _Problem(
        function, dim, inputs, outputs, labels_in, labels_out, device, backend, max_blocks,
        block_dim, list(mask or []),
    )  # fmt: skip


def _select_pairs(p: _Problem) -> list[tuple[int, int]]:
    """The (input, output) index pairs to differentiate, after ``p.outputs`` is known."""
    p.output_labels = p.output_labels or [f"output_{i}" for i in range(len(p.outputs))]
    wanted = {
        (_resolve_index(i, p.input_labels, "input"), _resolve_index(o, p.output_labels, "output"))
        for i, o in p.pairs
    }
    pairs = [
        (i, o)
        for i, x in enumerate(p.inputs)
        for o, y in enumerate(p.outputs)
        if _differentiable(x) and _differentiable(y) and (not wanted or (i, o) in wanted)
    ]
    if not pairs:
        raise KdslError(
            f"'{p.name}': nothing to differentiate; Jacobians are taken between input and "
            "output arrays of float dtype created with requires_grad=True"
        )
    return pairs


def _limit(n: int, limit: int) -> int:
    return n if limit <= 0 else min(n, limit)


def jacobian(
    function: Any,
    dim: Any = None,
    inputs: Sequence[Any] | None = None,
    outputs: Sequence[Any] | None = None,
    input_output_mask: Sequence[tuple[str | int, str | int]] | None = None,
    device: Any = None,
    max_blocks: int = 0,
    block_dim: int = 256,
    max_outputs_per_var: int = -1,
    restore_inputs: bool = True,
    backend: Any = None,
) -> Jacobians:
    """The Jacobians of ``function`` from its adjoint (reverse mode), one backward pass
    per output element. Rows past ``max_outputs_per_var`` (when > 0) are NaN.

    The gradients of the arguments are left as they were; a Python function's input
    arrays are restored after it runs when ``restore_inputs`` (default).
    """
    p = _problem(
        function, dim, inputs, outputs, input_output_mask, device, backend, max_blocks,
        block_dim, need_backward=True,
    )  # fmt: skip
    tape = Tape()
    snapshot = _Snapshot(p.inputs) if restore_inputs and not p.is_kernel else None
    try:
        if p.is_kernel:
            tape.record_launch(
                p.function, p.dim, p.inputs, p.outputs, p.device, max_blocks, block_dim,
                backend=backend,
            )  # fmt: skip
        else:
            with tape:
                p.outputs = p.run()
            if not tape.launches:
                raise KdslError(
                    f"'{p.name}' recorded nothing to differentiate: it launched no kernel (a "
                    "function that opens its own Tape records its launches there, not on "
                    "jacobian()'s tape)"
                )
        return _adjoint_jacobians(p, _select_pairs(p), tape, max_outputs_per_var)
    finally:
        if snapshot is not None:
            snapshot.restore()


def _adjoint_jacobians(
    p: _Problem, pairs: list[tuple[int, int]], tape: Tape, max_rows: int
) -> Jacobians:
    for a in _unique_arrays(p.inputs + p.outputs):
        tape.get_adjoint(a)
    saved = {id(a): (g, g.numpy().copy()) for a, g in tape.gradients.items()}
    jacs: Jacobians = {
        (i, o): np.full((_size(p.outputs[o]), _size(p.inputs[i])), np.nan) for i, o in pairs
    }
    try:
        for o in sorted({o for _, o in pairs}):
            out = p.outputs[o]
            for k in range(_limit(_size(out), max_rows)):
                tape.zero()
                _set_flat(out.grad, k, 1.0)
                tape.backward()
                for i, o2 in pairs:
                    if o2 == o:
                        jacs[i, o][k] = _host(p.inputs[i].grad)
    finally:
        for g, data in saved.values():
            _assign_host(g, data)
    return jacs


def _width(a: array) -> int:
    return int(np.prod(a._inner, dtype=np.int64)) if a._inner else 1


def _size(a: array) -> int:
    """Number of scalars in ``a`` (elements times components)."""
    return a.size * _width(a)


def jacobian_fd(
    function: Any,
    dim: Any = None,
    inputs: Sequence[Any] | None = None,
    outputs: Sequence[Any] | None = None,
    input_output_mask: Sequence[tuple[str | int, str | int]] | None = None,
    device: Any = None,
    max_blocks: int = 0,
    block_dim: int = 256,
    max_inputs_per_var: int = -1,
    eps: float = 1e-4,
    restore_inputs: bool = True,
    backend: Any = None,
) -> Jacobians:
    """The Jacobians of ``function`` by central differences, ``(f(x+eps) - f(x-eps)) / 2eps``
    per input element. Columns past ``max_inputs_per_var`` (when > 0) are NaN.

    Every evaluation starts from the original data: a kernel's input and output
    arrays are put back before each launch and at the end (an accumulating kernel
    sees its original outputs each time); a Python function's inputs are put back
    when ``restore_inputs`` (default) and its launches are kept off any active tape.
    """
    if not (isinstance(eps, int | float) and eps > 0):
        raise KdslError(f"eps must be a positive number, got {eps!r}")
    p = _problem(
        function, dim, inputs, outputs, input_output_mask, device, backend, max_blocks,
        block_dim, need_backward=False,
    )  # fmt: skip
    restore = p.is_kernel or restore_inputs
    snapshot = _Snapshot(p.inputs + p.outputs) if restore else None

    def evaluate(x: array, j: int, value: float) -> list[np.ndarray]:
        # Each evaluation starts from the original data, then moves one scalar.
        if snapshot is not None:
            snapshot.restore()
        _set_flat(x, j, value)
        with Tape():  # a private tape keeps these launches off the caller's
            outs = p.run()
        return [_host(y) for y in outs]

    try:
        if not p.is_kernel:
            with Tape():
                p.outputs = p.run()
            if snapshot is not None:
                snapshot.restore()  # the run may have changed the inputs
        pairs = _select_pairs(p)
        jacs: Jacobians = {
            (i, o): np.full((_size(p.outputs[o]), _size(p.inputs[i])), np.nan) for i, o in pairs
        }
        for i in sorted({i for i, _ in pairs}):
            x = p.inputs[i]
            base = _host(x)
            for j in range(_limit(base.size, max_inputs_per_var)):
                left = evaluate(x, j, base[j] - eps)
                right = evaluate(x, j, base[j] + eps)
                _set_flat(x, j, base[j])
                for i2, o in pairs:
                    if i2 == i:
                        jacs[i, o][:, j] = (right[o] - left[o]) / (2.0 * eps)
    finally:
        if snapshot is not None:
            snapshot.restore()
    return jacs


def gradcheck(
    function: Any,
    dim: Any = None,
    inputs: Sequence[Any] | None = None,
    outputs: Sequence[Any] | None = None,
    *,
    eps: float = 1e-4,
    atol: float = 1e-3,
    rtol: float = 1e-2,
    raise_exception: bool = True,
    input_output_mask: Sequence[tuple[str | int, str | int]] | None = None,
    device: Any = None,
    max_blocks: int = 0,
    block_dim: int = 256,
    max_inputs_per_var: int = -1,
    max_outputs_per_var: int = -1,
    show_summary: bool = True,
    restore_inputs: bool = True,
    backend: Any = None,
) -> bool:
    """Whether the adjoint Jacobians of ``function`` match central finite differences.

    A pair passes when it has no NaN and ``|AD - FD| <= atol + rtol * |FD|`` holds for
    every element compared (the first ``max_outputs_per_var`` rows and
    ``max_inputs_per_var`` columns when those are > 0). ``show_summary`` prints a
    table with the worst error per pair; on failure ``raise_exception`` raises a
    ``GradcheckError`` (a ``ValueError`` too), else False is returned. See the
    module docstring for the arguments and for float32 precision.
    """
    common = dict(
        dim=dim, inputs=inputs, outputs=outputs, input_output_mask=input_output_mask,
        device=device, max_blocks=max_blocks, block_dim=block_dim, backend=backend,
        restore_inputs=restore_inputs,
    )  # fmt: skip
    ad = jacobian(function, max_outputs_per_var=max_outputs_per_var, **common)
    fd = jacobian_fd(function, max_inputs_per_var=max_inputs_per_var, eps=eps, **common)
    p = _problem(
        function, dim, inputs, outputs, None, device, backend, max_blocks, block_dim, False
    )
    labels_out = p.output_labels or [f"output_{o}" for o in range(max(o for _, o in ad) + 1)]
    rows, failures = [], []
    for (i, o), jad in ad.items():
        rows_n = _limit(jad.shape[0], max_outputs_per_var)
        cols_n = _limit(jad.shape[1], max_inputs_per_var)
        a, f = jad[:rows_n, :cols_n], fd[i, o][:rows_n, :cols_n]
        row = _compare(a, f, atol, rtol)
        rows.append([p.input_labels[i], labels_out[o], *row])
        if row[-1] != "PASS":
            failures.append(
                f"{p.input_labels[i]} -> {labels_out[o]}: {row[-1]}, max abs error {row[0]}"
            )
    if show_summary:
        _print_table(
            ["Input", "Output", "Max Abs Error", "AD at MAE", "FD at MAE", "Max Rel Error", "Pass"],
            rows,
        )
        print(f"Gradient check for '{p.name}' {'failed' if failures else 'passed'}")
    if failures and raise_exception:
        raise GradcheckError(
            f"gradient check of '{p.name}' failed (atol={atol}, rtol={rtol}, eps={eps}):\n  "
            + "\n  ".join(failures)
            + "\n(finite differences of float32 kernels are noisy: check a float64 version, "
            "or loosen atol/rtol)"
        )
    return not failures


def _compare(ad: np.ndarray, fd: np.ndarray, atol: float, rtol: float) -> list[str]:
    """Summary cells for one Jacobian pair; the last is PASS, FAIL or NaN."""
    if ad.size == 0:
        return ["0", "-", "-", "0", "PASS"]
    err = np.abs(ad - fd)
    at = np.unravel_index(int(np.nanargmax(err)) if not np.all(np.isnan(err)) else 0, err.shape)
    rel = np.nanmax(err / (np.abs(fd) + 1e-8)) if not np.all(np.isnan(err)) else np.nan
    if np.isnan(ad).any():
        verdict = "NaN"
    elif np.allclose(ad, fd, atol=atol, rtol=rtol):
        verdict = "PASS"
    else:
        verdict = "FAIL"
    where = tuple(int(x) for x in at)
    return [f"{err[at]:.3e} at {where}", f"{ad[at]:.3e}", f"{fd[at]:.3e}", f"{rel:.3e}", verdict]


def _print_table(header: list[str], rows: list[list[str]]) -> None:
    widths = [max(len(str(r[c])) for r in [header, *rows]) for c in range(len(header))]
    for r in [header, *rows]:
        print(" | ".join(str(v).ljust(w) for v, w in zip(r, widths)))


def gradcheck_tape(
    tape: Tape,
    *,
    eps: float = 1e-4,
    atol: float = 1e-3,
    rtol: float = 1e-2,
    raise_exception: bool = True,
    input_output_masks: dict[str, Sequence[tuple[str | int, str | int]]] | None = None,
    blacklist_kernels: Sequence[str] | None = None,
    whitelist_kernels: Sequence[str] | None = None,
    max_inputs_per_var: int = -1,
    max_outputs_per_var: int = -1,
    show_summary: bool = True,
    reverse_launches: bool = False,
    skip_to_launch_index: int = 0,
) -> bool:
    """``gradcheck`` every kernel launch recorded on ``tape`` (functions recorded with
    ``record_func`` and kernels with ``enable_backward=False`` are skipped).

    Kernels are named by ``kernel.key`` or ``kernel.name`` in the masks and lists.
    Each launch is checked on the current data of its arrays.
    """
    if not isinstance(tape, Tape):
        raise KdslError(f"gradcheck_tape() takes a kdsl.Tape, not {type(tape).__name__}")
    masks = input_output_masks or {}
    black, white = set(blacklist_kernels or ()), set(whitelist_kernels or ())
    steps = list(reversed(tape.launches)) if reverse_launches else list(tape.launches)
    ok = True
    for n, rec in enumerate(steps):
        if n < skip_to_launch_index or not isinstance(rec, LaunchRecord):
            continue
        names = {rec.kernel.key, rec.kernel.name}
        if (white and not names & white) or names & black:
            continue
        if not backward_enabled(rec.kernel):
            continue
        if not any(_differentiable(a) for a in rec.inputs) or not any(
            _differentiable(a) for a in rec.outputs
        ):
            continue
        mask = masks.get(rec.kernel.key, masks.get(rec.kernel.name))
        ok &= gradcheck(
            rec.kernel, rec.dim, rec.inputs, rec.outputs, eps=eps, atol=atol, rtol=rtol,
            raise_exception=raise_exception, input_output_mask=mask, device=rec.device,
            max_blocks=rec.max_blocks, block_dim=rec.block_dim,
            max_inputs_per_var=max_inputs_per_var, max_outputs_per_var=max_outputs_per_var,
            show_summary=show_summary, backend=rec.backend,
        )  # fmt: skip
    return ok
