"""Measurements of a scene: error against run time, the largest stable dt, what compiled.

- ``run_scene``: one warm-up step (the compile, timed apart), then ``steps`` timed
  steps from the initial state; the error against the float64 reference and the
  energy drift.
- ``stable_dt``: the largest stable dt by bisection to 5%. A run is stable when, over
  ``horizon`` steps, the state stays finite and the scene's ``stability_measure``
  (the energy, by default) stays below ``GROWTH_BOUND`` times its initial value.
- ``diagnose_blowup``: reruns a blow-up with kdsl's fp-check (``verify_fp``), which
  stops at the first NaN or Inf stored, naming the step, the kernel and its line.
- ``compile_info``: per kernel the scene launched, what the compile driver built
  (``kdsl.compiler.record_compiles``).
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from kdsl.scenes import scene_class
from kdsl.scenes.base import PRECISIONS, check_choice, check_dt
from kdsl.scenes.binding import SceneError, bind, is_kdsl

#: How much the stability measure may grow over the horizon before a run is unstable.
GROWTH_BOUND = 100.0
#: Steps between host-side checks of a stability run.
CHECK_EVERY = 50
#: Bisection stops when hi / lo <= this.
BISECTION_TOLERANCE = 1.05


def make_scene(name: str, precision: str = "f32", integrator: str | None = None,
               backend: str = "cpu", binding: str = "kdsl", **params: Any) -> Any:  # fmt: skip
    """The scene ``name`` on ``backend`` ("cpu", "cuda" or "interp"), checked input."""
    cls = scene_class(name)
    check_choice("precision", precision, list(PRECISIONS))
    wp = bind(binding)
    device = _device(wp, backend)
    kdsl_backend = backend if is_kdsl(wp) and backend == "interp" else None
    if is_kdsl(wp):
        from kdsl.backends.registry import get_backend

        caps = get_backend("cuda" if backend == "cuda" else backend).capabilities
        if PRECISIONS[precision][1] not in caps:
            raise SceneError(f"backend {backend!r} has no {precision} (it has: {sorted(caps)})")
    return cls(wp, precision, integrator, device=device, backend=kdsl_backend, **params)


def available_backends() -> list[str]:
    """The backends a scene can run on here."""
    import kdsl

    return ["cpu", "interp"] + (["cuda"] if kdsl.is_cuda_available() else [])


def _device(wp: Any, backend: str) -> str:
    choices = ["cpu", "interp", "cuda"]
    check_choice("backend", backend, choices)
    if backend == "cuda":
        if not wp.is_cuda_available():
            raise SceneError(f"backend 'cuda' is not available here (available: "
                             f"{', '.join(available_backends())})")  # fmt: skip
        return "cuda:0"
    return "cpu"


@dataclass
class RunResult:
    """One ``run_scene``: the settings, the times (seconds) and the errors."""

    scene: str
    backend: str
    precision: str
    integrator: str
    dt: float
    steps: int
    t_end: float
    compile_s: float
    wall_s: float
    step_us: float
    error: float
    error_what: str
    energy_drift: float | None
    pde_error: float | None = None
    kernels_compiled: int = 0
    params: dict[str, Any] = field(default_factory=dict)
    #: A scene's further errors (``Scene.extra_errors``: nbody's momentum, throw's miss).
    extra: dict[str, float] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """The result as JSON-ready data."""
        return asdict(self)


def run_scene(scene: Any, dt: float, steps: int, backend: str = "cpu",
              measure_error: bool = True) -> RunResult:  # fmt: skip
    """Time ``steps`` steps of ``dt`` (after one untimed compile step) and measure the error.

    ``measure_error=False`` skips the reference (the error is NaN): for timing probes.
    """
    dt = check_dt(dt)
    if steps < 1:
        raise SceneError(f"steps must be >= 1, not {steps}")
    wp = scene.wp
    compiled = 0
    start = time.perf_counter()
    if is_kdsl(wp):
        from kdsl.compiler import record_compiles

        with record_compiles() as records:
            scene.step(dt)
            wp.synchronize_device(scene.device)
        compiled = len(records)
    else:
        scene.step(dt)
        wp.synchronize_device(scene.device)
    compile_s = time.perf_counter() - start
    scene.reset()
    e0 = scene.energy(*scene.state())
    wp.synchronize_device(scene.device)
    start = time.perf_counter()
    for _ in range(steps):
        scene.step(dt)
    wp.synchronize_device(scene.device)
    wall = time.perf_counter() - start
    e1 = scene.energy(*scene.state())
    drift = None if e0 is None or e1 is None else (e1 - e0) / max(abs(e0), 1e-300)
    error, pde, extra = math.nan, None, {}
    if measure_error:
        error = scene.error()
        pde = scene.pde_error() if hasattr(scene, "pde_error") else None
        extra = scene.extra_errors() if hasattr(scene, "extra_errors") else {}
    return RunResult(scene.name, backend, scene.precision, scene.integrator, dt, steps, scene.t,
                     compile_s, wall, 1e6 * wall / steps, error, scene.error_what, drift,
                     pde, compiled, dict(scene.params), extra)  # fmt: skip


# --------------------------------------------------------------------------- stability


@dataclass
class Trial:
    """One stability run: stable or not, and why not."""

    stable: bool
    reason: str = ""
    step: int | None = None


def try_dt(scene: Any, dt: float, horizon: int) -> Trial:
    """Run ``horizon`` steps of ``dt`` from the initial state; stable (see the module doc)?"""
    scene.reset()
    m0 = max(scene.stability_measure(*scene.state()), 1e-300)
    for k in range(1, horizon + 1):
        scene.step(dt)
        if k % CHECK_EVERY and k != horizon:
            continue
        x, v = scene.state()
        if not (np.all(np.isfinite(x)) and (v is None or np.all(np.isfinite(v)))):
            return Trial(False, "non-finite state", k)
        m = scene.stability_measure(x, v)
        if not math.isfinite(m) or m > GROWTH_BOUND * m0:
            return Trial(False, f"energy grew {m / m0:.3g}x", k)
    return Trial(True)


@dataclass
class StabilityResult:
    """The largest stable dt of one integrator and precision, with theory beside it."""

    integrator: str
    precision: str
    dt_max: float | None
    bound: str  # "measured", "above" (stable at every dt tried), "below" (at none)
    theory: float | None
    drift: float | None
    drift_dt: float
    blowup: str | None = None

    def as_dict(self) -> dict[str, Any]:
        """The result as JSON-ready data."""
        return asdict(self)


def stable_dt(scene: Any, horizon: int, dt0: float, span: float = 1e4) -> tuple[float | None, str, Trial | None]:  # fmt: skip
    """The largest stable dt (bisection to 5%) searched from ``dt0`` within ``dt0 * span^+-1``.

    Returns (dt, bound, the first unstable trial seen at the limit): bound is "measured",
    "above" when every dt up to ``dt0 * span`` was stable, "below" when none down to
    ``dt0 / span`` was.
    """
    lo = hi = dt0
    bad: Trial | None = None
    trial = try_dt(scene, dt0, horizon)
    if trial.stable:
        while True:
            hi = lo * 2.0
            if hi > dt0 * span:
                return lo, "above", None
            t = try_dt(scene, hi, horizon)
            if not t.stable:
                bad = t
                break
            lo = hi
    else:
        bad = trial
        while True:
            lo = hi / 2.0
            if lo < dt0 / span:
                return None, "below", bad
            if try_dt(scene, lo, horizon).stable:
                break
            hi = lo
    while hi / lo > BISECTION_TOLERANCE:
        mid = math.sqrt(lo * hi)
        t = try_dt(scene, mid, horizon)
        if t.stable:
            lo = mid
        else:
            hi, bad = mid, t
    return lo, "measured", bad


def energy_drift(scene: Any, dt: float, steps: int) -> float | None:
    """Relative energy change over ``steps`` steps of ``dt`` (None without an energy)."""
    scene.reset()
    e0 = scene.energy(*scene.state())
    for _ in range(steps):
        scene.step(dt)
    e1 = scene.energy(*scene.state())
    if e0 is None or e1 is None:
        return None
    return (e1 - e0) / max(abs(e0), 1e-300)


def diagnose_blowup(scene: Any, dt: float, steps: int) -> str:
    """The first step and kernel that stored a NaN or Inf at ``dt`` (kdsl's fp-check)."""
    from kdsl import config
    from kdsl.errors import KdslRuntimeError

    if not is_kdsl(scene.wp):
        return "fp-check needs the kdsl binding"
    scene.reset()
    saved, config.verify_fp = config.verify_fp, True
    try:
        for k in range(1, steps + 1):
            try:
                scene.step(dt)
            except KdslRuntimeError as e:
                first = str(e).splitlines()[0]
                return f"step {k}: {first}"
    finally:
        config.verify_fp = saved
    return f"no NaN/Inf stored within {steps} steps (the energy grew instead)"


def stability(scene_name: str, integrators: list[str], precisions: list[str], horizon: int,
              drift_steps: int, drift_dt: float | None, backend: str = "cpu",
              **params: Any) -> list[StabilityResult]:  # fmt: skip
    """``stable_dt`` and ``energy_drift`` per integrator and precision."""
    out = []
    for integ in integrators:
        for prec in precisions:
            scene = make_scene(scene_name, prec, integ, backend, **params)
            dt0 = check_dt(drift_dt or scene.default_dt)
            dt, bound, bad = stable_dt(scene, horizon, dt0)
            blowup = None
            if bad is not None and bad.reason == "non-finite state" and bound != "above":
                hi = dt * BISECTION_TOLERANCE if dt else dt0
                blowup = f"at dt={hi:.4g}: " + diagnose_blowup(scene, hi, bad.step or horizon)
            drift = energy_drift(scene, dt0, drift_steps)
            out.append(StabilityResult(integ, prec, dt, bound, scene.theory_dt_limit(integ),
                                       drift, dt0, blowup))  # fmt: skip
    return out


# --------------------------------------------------------------------------- info


@dataclass
class KernelInfo:
    """What the compile driver built for one kernel of a scene."""

    kernel: str
    ops: int
    features: list[str]
    adjoint: bool
    code_bytes: int | None
    compile_s: float

    def as_dict(self) -> dict[str, Any]:
        """The record as JSON-ready data."""
        return asdict(self)


def compile_info(scene: Any, dt: float) -> list[KernelInfo]:
    """Compile what one step of ``scene`` launches (cold: no kernel cache) and list it."""
    import os

    from kdsl.compiler import record_compiles
    from kdsl.runtime.launch import forget

    # Kernels compiled earlier in this process (the factories share them) compile again.
    for namespace in (scene.k, scene.stepper.k):
        for kernel in vars(namespace).values():
            if hasattr(kernel, "build_module"):
                forget(kernel)
    saved = os.environ.get("KDSL_CACHE")
    os.environ["KDSL_CACHE"] = "0"  # cold compile times, not cache loads
    try:
        with record_compiles() as records:
            scene.step(check_dt(dt))
            scene.wp.synchronize_device(scene.device)
    finally:
        if saved is None:
            del os.environ["KDSL_CACHE"]
        else:
            os.environ["KDSL_CACHE"] = saved
    return [KernelInfo(r.symbol, r.op_count, sorted(r.features.names), r.adjoint, r.code_bytes,
                       r.seconds) for r in records]  # fmt: skip
