"""``kdsl.Tape``: record kernel launches, then replay their adjoints in reverse.

A tape is active inside ``with tape:``. Every ``kdsl.launch`` made while one is
active (unless ``record_tape=False``) is recorded on the innermost active tape,
and so are ``kdsl.copy`` / ``array.assign`` between arrays that both have
gradients. ``tape.backward(loss=l)`` seeds ``l.grad`` with 1 and runs, newest
first, each launch's adjoint (``kdsl.runtime.adjoint.launch_adjoint``) with
every array argument's ``.grad`` as its adjoint (None, i.e. no gradient, for
arrays without one). Adjoint kernels add into input gradients, so gradients
accumulate over calls until ``tape.zero()``, as in Warp.

Differences from Warp: tapes may nest (the innermost active one records; Warp
raises), and replaying a launch of a kernel built with ``enable_backward=False``
raises a ``KdslError`` when any of its arrays has a gradient (Warp warns and
skips it, which silently gives wrong gradients). ``Tape.visualize`` is not
provided.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import Any, NamedTuple

import numpy as np

from kdsl import config
from kdsl.errors import KdslError, api_boundary
from kdsl.ir.types import StructType
from kdsl.runtime.array import array
from kdsl.runtime.array_access import check_launch, clear_read_marks
from kdsl.runtime.device import Device, get_device
from kdsl.runtime.modules import backward_enabled
from kdsl.runtime.stream import current_stream
from kdsl.runtime.zero_batch import zero_arrays

# The active tapes, outermost first; launch() records on the last one.
ACTIVE: list[Tape] = []


def active_tape() -> Tape | None:
    """The tape that records launches now (the innermost active one), or None."""
    return ACTIVE[-1] if ACTIVE else None


class LaunchRecord(NamedTuple):
    """One recorded launch. The first seven fields are in Warp's order, so Warp code
    that unpacks ``tape.launches[i][:7]`` keeps working."""

    kernel: Any
    dim: Any
    max_blocks: int
    inputs: list
    outputs: list
    device: Any
    block_dim: int
    metadata: dict
    backend: Any = None
    stream: Any = None


def _side_streams(launches: Sequence[Any]) -> list[tuple[Any, Any]]:
    """(stream, its device's current stream) for each recorded stream that is not the
    current one of its device (by identity: a ``Stream`` hashes through CuPy)."""
    found: dict[int, Any] = {}
    for rec in launches:
        s = getattr(rec, "stream", None)
        if s is not None and id(s) not in found:
            found[id(s)] = s
    if not found:
        return []
    pairs = []
    for s in found.values():
        current = current_stream(s.device)
        if current is not s and current.cuda_stream != s.cuda_stream:
            pairs.append((s, current))
    return pairs


def _site(rec: LaunchRecord) -> str:
    caller = rec.metadata.get("caller")
    return f" (launched at {caller['file']}:{caller['lineno']})" if caller else ""


def _kernel_name(kernel: Any) -> str:
    return getattr(kernel, "name", None) or getattr(kernel, "key", "?")


class Tape:
    """Records launches for reverse-mode differentiation (see the module docstring).

    Attributes: ``launches`` (``LaunchRecord``s and ``record_func`` callables, in
    order), ``gradients`` (array -> its gradient array, for every array whose
    gradient the tape has used), ``scopes`` (from ``record_scope_begin/end``).
    """

    def __init__(self) -> None:
        self.gradients: dict[Any, array] = {}
        self.launches: list[LaunchRecord | Callable[[], Any]] = []
        self.scopes: list[tuple[int, str | None, dict | None]] = []
        self.loss: array | None = None

    # --- recording -----------------------------------------------------------
    def __enter__(self) -> Tape:
        ACTIVE.append(self)
        return self

    def __exit__(self, *exc: object) -> None:
        if not ACTIVE or ACTIVE[-1] is not self:
            raise KdslError("Tape exited out of order: the innermost active tape must exit first")
        ACTIVE.pop()

    def record_launch(
        self,
        kernel: Any,
        dim: Any,
        inputs: Sequence[Any] = (),
        outputs: Sequence[Any] = (),
        device: Any = None,
        max_blocks: int = 0,
        block_dim: int = 256,
        metadata: dict | None = None,
        backend: Any = None,
        stream: Any = None,
    ) -> None:
        """Record a launch as ``kdsl.launch`` does on an active tape (without running it)."""
        rec = LaunchRecord(
            kernel, dim, max_blocks, list(inputs), list(outputs),
            device if type(device) is Device else get_device(device),
            block_dim, metadata or {}, backend, stream,
        )  # fmt: skip
        self.launches.append(rec)
        for a in (*rec.inputs, *rec.outputs):
            self.get_adjoint(a)
        if config.verify_autograd_array_access:
            check_launch(kernel, [*rec.inputs, *rec.outputs])

    def record_func(self, backward: Callable[[], Any], arrays: Iterable[Any]) -> None:
        """Record a Python step: ``backward()`` runs at its place in the reverse pass.

        ``arrays`` are the arrays whose gradients ``backward`` reads or writes; each
        must have a gradient (``requires_grad=True``), so ``zero()`` can clear it.
        """
        if not callable(backward):
            raise KdslError(
                f"record_func(): backward must be callable, not {type(backward).__name__}"
            )
        for a in arrays:
            if not isinstance(a, array) or a.grad is None:
                raise KdslError(
                    f"record_func(): {a!r:.60} is not a kdsl array with a gradient; "
                    "create it with requires_grad=True"
                )
            self.gradients[a] = a.grad
        self.launches.append(backward)

    def record_scope_begin(self, scope_name: str, metadata: dict | None = None) -> None:
        """Open a named group of the launches recorded next (for inspection only)."""
        self.scopes.append((len(self.launches), scope_name, metadata or {}))

    def record_scope_end(self, remove_scope_if_empty: bool = True) -> None:
        """Close the innermost open scope (dropped when it recorded nothing, by default)."""
        depth = sum(1 if name is not None else -1 for _, name, _ in self.scopes)
        if depth <= 0:
            raise KdslError("record_scope_end(): no scope is open")
        last = self.scopes[-1]
        if remove_scope_if_empty and last[1] is not None and last[0] == len(self.launches):
            self.scopes.pop()
        else:
            self.scopes.append((len(self.launches), None, None))

    # --- gradients -----------------------------------------------------------
    def get_adjoint(self, a: Any) -> array | None:
        """The gradient array a launch argument ``a`` uses (None: no gradient).

        Arrays with a ``.grad`` are tracked in ``gradients``; everything else
        (scalars, vectors, arrays without gradients) has no adjoint.
        """
        ta = type(a)
        if ta is array or isinstance(a, array):
            g = a.grad
            if g is not None:
                self.gradients[a] = g
            return g
        if ta in _PLAIN or isinstance(a, np.ndarray):  # a number, vector, matrix: no fields
            return None
        # A struct's adjoint is built at the adjoint launch; its array fields' gradients
        # are tracked here, so ``tape.gradients[s.field]`` and ``zero()`` reach them (Warp).
        for field, grad in _struct_field_grads(a):
            self.gradients[field] = grad
        return None

    @api_boundary
    def backward(self, loss: array | None = None, grads: dict[array, array] | None = None) -> None:
        """Run the recorded launches' adjoints, newest first.

        ``loss``: a one-element array with ``requires_grad=True``; its gradient is
        set to 1. ``grads``: array -> incoming gradient, copied into the array's
        ``.grad`` (or made its ``.grad`` when it has none). Gradients of every
        recorded input accumulate (+=); call ``zero()`` between independent passes.
        """
        if loss is not None:
            _seed_loss(loss)
            self.loss = loss
        for a, g in (grads or {}).items():
            if not isinstance(a, array) or not isinstance(g, array):
                raise KdslError("backward(grads=...) maps kdsl arrays to kdsl arrays")
            if a.grad is None:
                a.grad = g
            else:
                a.grad.assign(g)
            self.gradients[a] = a.grad
        # Adjoints replay on their launch's stream; the seeds above, ``zero()`` and what
        # reads the gradients after run on the current one: order the two both ways.
        side = _side_streams(self.launches)
        for s, current in side:
            s.wait_stream(current)
        for step in reversed(self.launches):
            if isinstance(step, LaunchRecord):
                self._replay(step)
            else:
                step()
        for s, current in side:
            current.wait_stream(s)
        if config.verify_autograd_array_access:
            self._clear_read_marks()  # later writes can no longer corrupt these gradients

    def _clear_read_marks(self) -> None:
        recorded = [a for r in self.launches if isinstance(r, LaunchRecord)
                    for a in (*r.inputs, *r.outputs)]  # fmt: skip
        clear_read_marks([*recorded, *self.gradients])

    def _replay(self, rec: LaunchRecord) -> None:
        args = [*rec.inputs, *rec.outputs]
        adj = [self.get_adjoint(a) for a in args]
        if all(g is None for g in adj) and not any(_struct_field_grads(a) for a in args):
            return  # no argument carries a gradient: the adjoint would change nothing
        if not backward_enabled(rec.kernel):
            raise KdslError(
                f"tape.backward(): kernel '{_kernel_name(rec.kernel)}' was declared with "
                f"enable_backward=False, so its recorded launch{_site(rec)} cannot be "
                "differentiated; remove enable_backward=False, or launch it with "
                "record_tape=False if it does not depend on what is differentiated"
            )
        launch_adjoint = _launch_adjoint()
        launch_adjoint(
            rec.kernel, rec.dim, args, adj, device=rec.device, stream=rec.stream,
            backend=rec.backend,
        )  # fmt: skip

    def zero(self) -> None:
        """Set every gradient the tape has used to zero (in one pass per device, see
        ``kdsl.runtime.zero_batch``)."""
        zero_arrays(list(self.gradients.values()))

    def reset(self) -> None:
        """Zero the gradients, then forget every recorded launch, function and scope."""
        if config.verify_autograd_array_access:
            self._clear_read_marks()
        self.zero()
        self.launches = []
        self.scopes = []
        self.gradients = {}
        self.loss = None


_ADJOINT: list = []


def _launch_adjoint() -> Callable[..., None]:
    """``kdsl.runtime.adjoint.launch_adjoint`` (imported on first use: adjoint imports
    launch, which imports this module; an import statement costs microseconds)."""
    if not _ADJOINT:
        from kdsl.runtime.adjoint import launch_adjoint

        _ADJOINT.append(launch_adjoint)
    return _ADJOINT[0]


#: Argument types that never carry a gradient (numbers), checked before the general rule.
_PLAIN = frozenset({int, float, bool, np.float16, np.float32, np.float64, np.int8, np.int16,
                    np.int32, np.int64, np.uint8, np.uint16, np.uint32, np.uint64, np.bool_})  # fmt: skip


def _struct_field_grads(value: Any) -> list[tuple[array, array]]:
    """(array, gradient) for every array field with a gradient in a struct value, nested
    structs included; [] for anything else."""
    t = getattr(value, "__kdsl_type__", None)
    if not isinstance(t, StructType):
        return []
    out = []
    for name, _ in t.fields:
        x = getattr(value, name, None)
        if isinstance(x, array):
            if x.grad is not None:
                out.append((x, x.grad))
        else:
            out += _struct_field_grads(x)
    return out


def _seed_loss(loss: Any) -> None:
    if not isinstance(loss, array):
        raise KdslError(f"backward(loss=...) takes a kdsl array, not {type(loss).__name__}")
    if loss.size != 1 or loss._inner:
        raise KdslError(
            f"backward(loss=...) needs a one-element scalar array (the loss); got shape "
            f"{loss.shape} of {loss.dtype.__name__ if hasattr(loss.dtype, '__name__') else loss.dtype}; "
            "use backward(grads={array: gradient}) for other outputs"
        )
    if loss.grad is None:
        raise KdslError(
            "backward(loss=...): the loss array has no gradient; create it with requires_grad=True"
        )
    loss.grad.fill_(1.0)


# --- copies ------------------------------------------------------------------
def record_copy(dest: array, src: array, dest_offset: int, src_offset: int, count: int) -> None:
    """Record ``kdsl.copy(dest, src, ...)`` on the active tape when both have gradients.

    Its adjoint moves the copied window of ``dest.grad`` into ``src.grad`` (+=) and
    zeroes that window of ``dest.grad`` (the values there were overwritten).
    """
    tape = active_tape()
    if tape is None or dest.grad is None or src.grad is None or count == 0:
        return
    tape.record_func(
        lambda: _adj_copy(dest, src, dest_offset, src_offset, count), arrays=[dest, src]
    )
    if config.verify_autograd_array_access:
        dest.mark_write(operation="an array copy")
        src.mark_read()


def _adj_copy(dest: array, src: array, dest_offset: int, src_offset: int, count: int) -> None:
    from kdsl.runtime import cuda_memory as mem
    from kdsl.runtime.alloc import copy, empty, zeros
    from kdsl.runtime.stream import get_stream

    dg, sg = dest.grad, src.grad
    if dg is None or sg is None:
        return
    # Gather the incoming window on src's device, then clear it in dest.grad before
    # adding into src.grad: right even when dest and src share memory.
    incoming = empty(count, dtype=dg.dtype, device=sg.device)
    copy(incoming, dg, 0, dest_offset, count)
    copy(dg, zeros(count, dtype=dg.dtype, device=dg.device), dest_offset, 0, count)
    current = empty(count, dtype=sg.dtype, device=sg.device)
    copy(current, sg, 0, src_offset, count)
    if sg.device.is_cpu and dg.device.is_cuda:
        get_stream(dg.device).synchronize()  # device-to-host copies are asynchronous
    with mem.scope(sg.device):
        current._buf += incoming._buf
    copy(sg, current, src_offset, 0, count)
