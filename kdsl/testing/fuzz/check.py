"""The fuzzer's oracles: what a fuzzed program must satisfy.

``check_valid`` runs a valid program through every stage and checks:

(a) nothing raises an internal error (``is_internal``);
(b) print -> parse -> print of the IR is exact at ``kir``, ``kir-opt`` and ``adjoint``,
    with and without debug info;
(c) every backend computes what the first one does, floats within ``ULPS`` units in
    the last place (at ``max(|value|, 1)``: the generator's values are O(1), so this
    bounds the absolute error of a cancellation too), integers exactly;
(d) for differentiable programs, ``Tape`` gradients of the float64 instance agree with
    central finite differences (``GRAD_RTOL``/``GRAD_ATOL``) wherever the loss is smooth
    (left and right one-sided slopes agree, and the central difference is stable when
    the step shrinks: see ``finite_difference``).

``check_invalid`` runs an invalid program and checks it raises a located, non-internal
``KdslError`` naming the marked line. Failures raise ``FuzzFailure``, whose message
holds the program's source.
"""

from __future__ import annotations

import hashlib
import importlib.util
import re
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from kdsl.errors import KdslError
from kdsl.testing.fuzz.program import MARK, N, Program

#: Allowed distance between backends, in units in the last place at max(|value|, 1).
ULPS = {"float16": 16, "float32": 512, "float64": 512}
#: Gradient tolerance: |ad - fd| <= GRAD_ATOL + GRAD_RTOL * |fd| (float64 kernels).
GRAD_RTOL = 1e-5
GRAD_ATOL = 1e-6
#: A slope counts as smooth when its left and right one-sided differences agree this well.
KINK_TOL = 1e-3
#: Random weights of the outputs in the gradient check's loss (fixed: results reproduce).
_WEIGHTS = np.random.default_rng(7).uniform(0.5, 1.5, size=N + 3)


class FuzzFailure(AssertionError):
    """A fuzzed program broke an oracle; ``kind`` names which, ``source`` is the program."""

    def __init__(self, kind: str, detail: str, source: str) -> None:
        self.kind = kind
        self.detail = detail
        self.source = source
        super().__init__(f"[{kind}] {detail}\n--- program ---\n{source}")

    def signature(self) -> str:
        """A short key that groups failures with the same cause (for de-duplication)."""
        first = self.detail.splitlines()[0] if self.detail else ""
        first = re.sub(r"\d+(\.\d+)?(e[-+]?\d+)?", "#", first)
        first = re.sub(r"'[^']*'", "'_'", first)
        return f"{self.kind}: {first[:120]}"


def is_internal(exc: BaseException) -> bool:
    """True for a kdsl bug: a non-kdsl exception, or a kdsl error that says it is one."""
    if not isinstance(exc, KdslError):
        return True
    if type(exc).__name__ == "PassCrashError":
        return True
    text = exc.message.lower()
    return re.search(r"\binternal\b", text) is not None or "kdsl bug" in text


def describe(exc: BaseException) -> str:
    """``Type: message`` with the innermost frame of the traceback (for reports)."""
    import traceback

    frames = traceback.extract_tb(exc.__traceback__)
    where = f" (at {Path(frames[-1].filename).name}:{frames[-1].lineno})" if frames else ""
    return f"{type(exc).__name__}: {exc}{where}"


# --------------------------------------------------------------------------- loading

_DIR: Path | None = None


def program_dir() -> Path:
    """The directory the fuzzer writes program files to (one per process)."""
    global _DIR
    if _DIR is None:
        _DIR = Path(tempfile.mkdtemp(prefix="kdsl-fuzz-"))
    return _DIR


def load(source: str) -> ModuleType:
    """Write ``source`` to a file and import it (so errors name a real file and line)."""
    digest = hashlib.sha1(source.encode()).hexdigest()[:16]
    name = f"kdsl_fuzz_{digest}"
    path = program_dir() / f"{name}.py"
    path.write_text(source)
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    finally:
        sys.modules.pop(name, None)
    return module


# --------------------------------------------------------------------------- oracles


def _guard(kind: str, source: str, fn: Any, *args: Any) -> Any:
    """Call ``fn``; any exception is a failure of ``kind`` (internal or not: the program is valid)."""
    try:
        return fn(*args)
    except FuzzFailure:
        raise
    except Exception as e:
        label = "internal" if is_internal(e) else "rejected-valid"
        raise FuzzFailure(f"{kind}/{label}", describe(e), source) from e


def check_roundtrip(kernel: Any, with_adjoint: bool) -> None:
    """(b): print -> parse -> print is exact at kir, kir-opt and adjoint (raises AssertionError)."""
    from kdsl.backends.registry import get_backend
    from kdsl.compiler import adjoint_module
    from kdsl.ir import parse_module, print_module
    from kdsl.passes import run_pipeline

    def roundtrip(module: Any, stage: str) -> None:
        for debuginfo in (False, True):
            text = print_module(module, debuginfo=debuginfo)
            again = print_module(parse_module(text, verify=True), debuginfo=debuginfo)
            if again != text:
                raise AssertionError(
                    f"stage {stage} (debuginfo={debuginfo}): {_first_diff(text, again)}"
                )

    module = kernel.build_module()
    roundtrip(module, "kir")
    run_pipeline(module, get_backend("cpu").pipeline)
    roundtrip(module, "kir-opt")
    if with_adjoint:
        roundtrip(adjoint_module(kernel), "adjoint")


def _first_diff(a: str, b: str) -> str:
    for n, (x, y) in enumerate(zip(a.splitlines(), b.splitlines()), 1):
        if x != y:
            return f"line {n}: printed {x.strip()!r}, reparsed {y.strip()!r}"
    return "the texts differ in length"


def run_outputs(module: ModuleType, backend: str) -> list[np.ndarray]:
    """Launch the program on ``backend``; its four outputs as NumPy arrays."""
    args = module.run(backend)
    return [np.array(a.numpy()) for a in args[4:8]]


def ulp_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """|a - b| in units in the last place of the dtype at max(|a|, |b|, 1); equal or both-NaN: 0."""
    eps = float(np.finfo(a.dtype).eps)
    x, y = a.astype(np.float64), b.astype(np.float64)
    with np.errstate(invalid="ignore", over="ignore"):
        scale = np.maximum(np.maximum(np.abs(x), np.abs(y)), 1.0)
        dist = np.abs(x - y) / (eps * scale)
    same = (x == y) | (np.isnan(x) & np.isnan(y))
    return np.where(same, 0.0, np.where(np.isnan(dist), np.inf, dist))


def compare_outputs(ref: list[np.ndarray], got: list[np.ndarray], names: tuple[str, str]) -> None:
    """(c): raise AssertionError where ``got`` and ``ref`` differ beyond the bounds."""
    labels = ("out", "iout", "acc", "iacc")
    for label, r, g in zip(labels, ref, got):
        if r.dtype.kind == "f":
            dist = ulp_distance(r, g)
            bound = ULPS[r.dtype.name] * (N if label == "acc" else 1)
            bad = dist > bound
        else:
            bad = r != g
        if np.any(bad):
            k = int(np.argwhere(bad)[0][0])
            raise AssertionError(
                f"{label}[{k}]: {names[0]} gives {r[k].item()!r}, {names[1]} gives {g[k].item()!r}"
                + (f" ({dist[k]:.3g} ulps > {bound})" if r.dtype.kind == "f" else "")
            )


def check_valid(program: Program, backends: Sequence[str] = ("interp", "cpu")) -> None:
    """Run every oracle on a valid ``program``; raise ``FuzzFailure`` on the first broken one."""
    source = program.source()
    module = _guard("import", source, load, source)
    _guard("roundtrip", source, check_roundtrip, module.fuzz_kernel, program.differentiable)
    results = {b: _guard(f"run-{b}", source, run_outputs, module, b) for b in backends}
    ref = backends[0]
    for b in backends[1:]:
        try:
            compare_outputs(results[ref], results[b], (ref, b))
        except AssertionError as e:
            raise FuzzFailure("mismatch", f"{ref} vs {b}: {e}", source) from None
    if program.differentiable:
        source64 = program.source("float64")
        module64 = _guard("import", source64, load, source64)
        for b in backends:
            _guard(f"gradient-{b}", source64, check_gradient, module64, b, source64)


# --------------------------------------------------------------------------- gradients


def device_of(backend: str) -> str:
    """The device a fuzzed program runs on for ``backend`` (as its ``run`` picks it)."""
    return "cuda" if backend == "cuda" else "cpu"


def _loss(module: ModuleType, backend: str, xs: np.ndarray) -> float:
    args = module.make_args(device=device_of(backend))
    args[0].assign(xs)
    module.run(backend, args)
    out, acc = args[4].numpy(), args[6].numpy()
    return float(np.dot(_WEIGHTS[:N], out) + np.dot(_WEIGHTS[N:], acc))


def finite_difference(module: ModuleType, backend: str, x0: np.ndarray, j: int) -> float | None:
    """The central difference of the loss in ``xs[j]``, or None where the loss is not smooth.

    Step control: with h = 1e-6 * max(|x|, 1), the left and right one-sided slopes must
    agree (KINK_TOL), and the central differences at h and h/4 must agree, else a kink,
    a jump (an integer cast, a branch) or a discontinuity lies within h of x.
    """
    h = 1e-6 * max(abs(float(x0[j])), 1.0)

    def at(delta: float) -> float:
        x = x0.copy()
        x[j] += delta
        return _loss(module, backend, x)

    f0 = at(0.0)
    fp, fm = at(h), at(-h)
    right, left = (fp - f0) / h, (f0 - fm) / h
    central = (fp - fm) / (2 * h)
    if not np.isfinite(central) or abs(right - left) > KINK_TOL * (1 + abs(central)):
        return None
    fine = (at(h / 4) - at(-h / 4)) / (h / 2)
    if abs(fine - central) > 10 * GRAD_RTOL * (1 + abs(central)):
        return None
    return fine


def check_gradient(module: ModuleType, backend: str, source: str = "") -> None:
    """(d): ``Tape`` gradients of the loss in ``xs`` agree with finite differences."""
    import kdsl as wp

    device = device_of(backend)
    args = module.make_args(requires_grad=True, device=device)
    x0 = args[0].numpy().astype(np.float64)
    tape = wp.Tape()
    with tape:
        module.run(backend, args)
    seeds = {
        args[4]: wp.array(_WEIGHTS[:N], dtype=wp.float64, device=device),
        args[6]: wp.array(_WEIGHTS[N:], dtype=wp.float64, device=device),
    }
    tape.backward(grads=seeds)
    ad = args[0].grad.numpy().astype(np.float64)
    for j in range(N):
        fd = finite_difference(module, backend, x0, j)
        if fd is None:
            continue
        if not abs(ad[j] - fd) <= GRAD_ATOL + GRAD_RTOL * abs(fd):
            raise FuzzFailure(
                f"gradient-{backend}",
                f"d loss / d xs[{j}]: tape gives {float(ad[j])!r}, finite differences {fd!r}",
                source,
            )


# --------------------------------------------------------------------------- invalid programs


def marked_line(source: str) -> int:
    """The line number of the ``MARK`` comment in an invalid program's source."""
    for n, line in enumerate(source.splitlines(), 1):
        if line.endswith(MARK):
            return n
    raise ValueError("an invalid program carries no marked line")


def check_invalid(program: Program, backends: Sequence[str] = ("interp", "cpu")) -> None:
    """An invalid program must raise a located ``KdslError`` at its marked line, on every backend."""
    source = program.source()
    line = marked_line(source)
    for backend in backends:
        try:
            module = load(source)
            module.run(backend)
        except Exception as e:
            if is_internal(e):
                raise FuzzFailure("invalid/internal", describe(e), source) from e
            loc = getattr(e, "loc", None)
            if loc is None or not loc.file.endswith(".py") or loc.line <= 0 or loc.col <= 0:
                raise FuzzFailure("invalid/unlocated", describe(e), source) from e
            if Path(loc.file).name.startswith("kdsl_fuzz_") and loc.line != line:
                raise FuzzFailure(
                    "invalid/misplaced",
                    f"error at line {loc.line}, expected {line}: {describe(e)}",
                    source,
                ) from e
            if not Path(loc.file).name.startswith("kdsl_fuzz_"):
                raise FuzzFailure(
                    "invalid/elsewhere", f"error located in {loc.file}: {describe(e)}", source
                ) from e
            continue
        raise FuzzFailure("invalid/accepted", f"{program.invalid}: no error on {backend}", source)
