"""Run conformance cases on a backend and compare with their NumPy references.

``targets()`` lists every (backend, device) pair the registry offers;
``run_case`` launches a case's kernel there and returns its output arrays;
``check_case`` compares them with the case's float64 reference and raises
``AssertionError`` naming the first mismatching element.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from kdsl.testing.case import Case, GradCase


@dataclass(frozen=True)
class Target:
    """One backend on one of its devices, with the backend's capabilities."""

    backend: str
    device: str
    capabilities: frozenset[str]

    def __str__(self) -> str:
        return f"{self.backend}:{self.device}"


def _backend_names() -> list[str]:
    from kdsl.backends import registry

    found = registry.available_backends()
    return [b if isinstance(b, str) else b.name for b in found]


def targets(backends: Iterable[str] | None = None) -> list[Target]:
    """(backend, device) pairs for ``backends`` (default: every registered backend).

    An unknown backend name raises ``KeyError`` with the names that exist.
    """
    from kdsl.backends import registry

    names = _backend_names()
    wanted = list(backends) if backends is not None else names
    out: list[Target] = []
    for name in wanted:
        if name not in names:
            raise KeyError(f"no backend named {name!r}; registered: {', '.join(names) or 'none'}")
        backend = registry.get_backend(name)
        caps = frozenset(backend.capabilities)
        for device in backend.devices():
            out.append(Target(name, str(device), caps))
    return out


def missing_capabilities(case: Case, target: Target) -> list[str]:
    """The capabilities ``case`` requires that ``target`` lacks."""
    return [c for c in case.requires if c not in target.capabilities]


def _to_arg(value: Any, arg_type: Any, device: str) -> Any:
    """A kernel argument from a NumPy input, in the type the kernel declares."""
    import kdsl
    from kdsl.ir import types as T
    from kdsl.runtime.dtypes import public_dtype

    if isinstance(arg_type, T.ArrayType):
        dtype = public_dtype(arg_type.dtype)  # structs too: a NumPy structured array
        return kdsl.from_numpy(np.array(value, copy=True), dtype=dtype, device=device)
    if isinstance(arg_type, T.StructType):  # one structured NumPy element
        return public_dtype(arg_type).from_numpy(value)
    return kdsl.class_of(arg_type)(value)


def run_case(
    case: Case, target: Target, inputs: dict[str, Any] | None = None
) -> dict[str, np.ndarray]:
    """Launch ``case`` on ``target``; returns the output arrays as NumPy arrays."""
    import kdsl

    if inputs is None:
        inputs = case.make_inputs(np.random.default_rng(case.seed))
    kernel = case.kernel
    names = list(kernel.arg_names)
    absent = [n for n in names if n not in inputs]
    if absent:
        raise ValueError(f"case {case.name}: make_inputs() gave no value for {absent}")
    args = {n: _to_arg(inputs[n], t, target.device) for n, t in zip(names, kernel.arg_types)}
    kdsl.launch(
        kernel,
        dim=case.dim,
        inputs=[args[n] for n in names],
        device=target.device,
        backend=target.backend,
    )
    return {name: np.asarray(args[name].numpy()) for name in case.outputs}


def compare(case: Case, name: str, actual: np.ndarray, expected: Any) -> None:
    """Raise AssertionError if ``actual`` differs from ``expected`` beyond tolerance."""
    expected = np.asarray(expected)
    if actual.shape != expected.shape:
        raise AssertionError(
            f"{case.name}: output {name!r} has shape {actual.shape}, expected {expected.shape}"
        )
    tol = case.tolerance(actual.dtype)
    ulps = case.ulps
    if tol is not None and ulps is not None:
        _compare_ulps(case, name, actual, expected, ulps)
        return
    if tol is None:
        want = expected.astype(actual.dtype)
        bad = actual != want
    else:
        rtol, atol = tol
        a = actual.astype(np.float64)
        want = expected.astype(np.float64)
        both_nan = np.isnan(a) & np.isnan(want)
        with np.errstate(invalid="ignore"):
            close = (a == want) | (np.abs(a - want) <= atol + rtol * np.abs(want))
        bad = ~(close | both_nan)
    if np.any(bad):
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        count = int(np.count_nonzero(bad))
        raise AssertionError(
            f"{case.name}: output {name!r} differs at {count} of {bad.size} elements; "
            f"first at index {idx}: got {actual[idx]!r}, expected {want[idx]!r}"
            + (f" (rtol={tol[0]}, atol={tol[1]})" if tol else " (exact)")
        )


def ulp_distance(actual: np.ndarray, expected: np.ndarray) -> np.ndarray:
    """|actual - expected| in units in the last place of ``actual``'s dtype at ``expected``.

    Equal values (infinities included) and two NaNs are 0 apart; a NaN against a number
    is infinitely far.
    """
    want = expected.astype(actual.dtype)
    with np.errstate(all="ignore"):
        step = np.spacing(np.abs(want)).astype(np.float64)
        dist = np.abs(actual.astype(np.float64) - expected.astype(np.float64)) / step
    same = (actual == want) | (np.isnan(actual) & np.isnan(expected))
    return np.where(same, 0.0, np.where(np.isnan(dist), np.inf, dist))


def _compare_ulps(case, name: str, actual: np.ndarray, expected: Any, ulps: int) -> None:
    expected = np.asarray(expected, dtype=np.float64)
    if actual.shape != expected.shape:
        raise AssertionError(
            f"{case.name}: output {name!r} has shape {actual.shape}, expected {expected.shape}"
        )
    dist = ulp_distance(actual, expected)
    bad = dist > ulps
    if np.any(bad):
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        raise AssertionError(
            f"{case.name}: output {name!r} differs at {int(np.count_nonzero(bad))} of "
            f"{bad.size} elements; first at index {idx}: got {actual[idx]!r}, expected "
            f"{expected[idx]!r} ({dist[idx]:.3g} ulps, {ulps} allowed)"
        )


def check_case(case: Case | GradCase, backend: str | Target, device: str | None = None) -> None:
    """Run ``case`` on a backend (name or Target) and check every output.

    With a backend name and no ``device``, the backend's first device is used.
    """
    if isinstance(backend, Target):
        target = backend
    else:
        found = [t for t in targets([backend]) if device is None or t.device == device]
        if not found:
            raise KeyError(f"backend {backend!r} has no device {device!r}")
        target = found[0]
    if isinstance(case, GradCase):
        check_gradients(case, target)
        return
    inputs = case.make_inputs(np.random.default_rng(case.seed))
    # The reference sees its own copy, so a kernel writing in place cannot change it.
    expected = case.reference({k: np.array(v, copy=True) for k, v in inputs.items()})
    actual = run_case(case, target, inputs)
    for name in case.outputs:
        compare(case, name, actual[name], expected[name])


def check_gradients(case: GradCase, target: Target) -> None:
    """Run ``kdsl.autograd.gradcheck`` for ``case`` on ``target``; AssertionError on a mismatch."""
    import kdsl
    from kdsl.autograd import gradcheck

    values = case.make_inputs(np.random.default_rng(case.seed))
    kernel = case.kernel
    args = []
    for n, t in zip(kernel.arg_names, kernel.arg_types):
        a = _to_arg(values[n], t, target.device)
        if n in case.inputs or n in case.outputs:
            a.requires_grad = True
        args.append(a)
    n_out = len(case.outputs)
    if list(kernel.arg_names[-n_out:]) != list(case.outputs):
        raise ValueError(f"case {case.name}: the outputs must be the kernel's last parameters")
    rtol, atol = case.tol
    common = dict(
        dim=case.dim, inputs=args[:-n_out], outputs=args[-n_out:], eps=case.eps, atol=atol,
        rtol=rtol, show_summary=False, device=target.device, backend=target.backend,
        input_output_mask=[(i, o) for i in case.inputs for o in case.outputs],
    )  # fmt: skip
    try:
        gradcheck(kernel, **common)
    except kdsl.KdslError as e:
        raise AssertionError(f"{case.name}: {e}") from None
