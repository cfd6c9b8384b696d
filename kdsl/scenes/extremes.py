"""``kdsl scene extremes NAME``: each scene on its stiff and extreme cases.

Per scene, a list of cases (``EXTREMES``): stiffness and mass-ratio sweeps, very
large and very small scales (1e-6 to 1e6 m), near-coincident particles, degenerate
cloth triangles, large offsets and times where float16/float32 cancel. Each case
runs in every precision asked for; the report gives the error against the float64
reference (and the scene's further errors) or, where a run went non-finite, the
first step and kernel that stored the NaN or Inf (kdsl's fp-check), not a NaN.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from kdsl.scenes.binding import SceneError, is_kdsl
from kdsl.scenes.measure import diagnose_blowup, make_scene, run_scene


@dataclass(frozen=True)
class Case:
    """One extreme case: what it probes, the scene parameters, integrator, dt and steps."""

    label: str
    params: dict[str, Any]
    integrator: str
    dt: float
    steps: int


def _sweep(label: str, key: str, values: list[float], integrators: tuple[str, ...], dt: float,
           steps: int, **base: Any) -> list[Case]:  # fmt: skip
    return [Case(f"{label} {key}={v:g}", {**base, key: v}, integ, dt, steps)
            for v in values for integ in integrators]  # fmt: skip


#: Scene name -> its extreme cases (small sizes: a report takes seconds to a minute).
EXTREMES: dict[str, list[Case]] = {
    "particles": _sweep(
        "stiff drag",
        "drag",
        [1e-6, 1.0, 1e2, 1e3],
        ("symplectic_euler", "backward_euler"),
        1e-2,
        100,
        count=64,
    ),
    "chain": (
        _sweep(
            "mass ratio",
            "mass_ratio",
            [1.0, 1e2, 1e4, 1e6],
            ("velocity_verlet", "backward_euler"),
            1e-2,
            200,
            count=8,
        )
        + _sweep(
            "stiffness",
            "stiffness",
            [1e2, 1e4, 1e6],
            ("velocity_verlet", "backward_euler"),
            1e-3,
            200,
            count=8,
        )
    ),
    "heat": _sweep("grid", "grid", [8, 32, 64], ("explicit_euler", "backward_euler"), 2e-4, 100),
    "wave": _sweep("grid", "grid", [8, 32, 64], ("velocity_verlet", "backward_euler"), 1e-2, 100),
    "cloth": (
        _sweep(
            "stiffness",
            "stiffness",
            [1e2, 1e4, 1e6],
            ("symplectic_euler", "backward_euler"),
            2e-4,
            100,
            grid=6,
        )
        + _sweep("scale", "scale", [1e-6, 1e6], ("symplectic_euler",), 2e-4, 100, grid=6)
        + _sweep(
            "degenerate triangles",
            "degenerate",
            [1],
            ("symplectic_euler", "backward_euler"),
            2e-4,
            100,
            grid=6,
        )
    ),
    "nbody": (
        _sweep("mass ratio", "mass_ratio", [1e3, 1e6], ("velocity_verlet",), 2e-3, 100, count=32)
        + _sweep("scale", "scale", [1e-6, 1e6], ("velocity_verlet",), 2e-3, 100, count=32)
        + _sweep(
            "near-coincident",
            "close",
            [1e-6],
            ("velocity_verlet",),
            2e-3,
            100,
            count=32,
            softening=1e-3,
        )
        + _sweep(
            "cancellation: offset", "offset", [1e2, 1e4], ("velocity_verlet",), 2e-3, 100, count=32
        )
    ),
    "stiff_odes": (
        _sweep("stiffness", "mu", [1e1, 1e2, 1e3, 1e4], ("backward_euler",), 1e-3, 100, count=64)
        + _sweep("stiffness", "mu", [1e1, 1e3], ("rk4",), 1e-4, 100, count=64)
    ),
    "ocean": (
        _sweep("cancellation: time", "t0", [0.0, 1e3, 1e5], ("analytic",), 1 / 60, 30, grid=32)
        + _sweep("host phase", "t0", [1e5], ("analytic",), 1 / 60, 30, grid=32, host_phase=1)
    ),
    "throw": _sweep(
        "drag", "drag", [1e-3, 1.0, 10.0], ("rk4", "symplectic_euler"), 1e-2, 5, count=16
    ),
}


@dataclass
class ExtremeResult:
    """One case in one precision: the error, further errors, or where it blew up."""

    case: str
    integrator: str
    precision: str
    dt: float
    steps: int
    error: float | None
    extra: dict[str, float] = field(default_factory=dict)
    blowup: str | None = None

    def as_dict(self) -> dict[str, Any]:
        """The result as JSON-ready data."""
        return asdict(self)


def run_extremes(name: str, precisions: list[str], backend: str = "cpu",
                 on_run: Any = None) -> list[ExtremeResult]:  # fmt: skip
    """Every extreme case of scene ``name`` in every precision."""
    if name not in EXTREMES:
        raise SceneError(f"scene {name!r} has no extreme cases (scenes with some: "
                         f"{', '.join(EXTREMES)})")  # fmt: skip
    out = []
    for case in EXTREMES[name]:
        for prec in precisions:
            if on_run:
                on_run(f"{case.label} {case.integrator} {prec}")
            # Overflow in float16 is what these cases probe: report it, don't warn about it.
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                scene = make_scene(name, prec, case.integrator, backend, **case.params)
                r = run_scene(scene, case.dt, case.steps, backend)
                x, v = scene.state()
                finite = bool(np.all(np.isfinite(x)) and (v is None or np.all(np.isfinite(v))))
                blowup = None
                error: float | None = r.error
                if not finite or not math.isfinite(r.error):
                    error = None
                    if not finite and is_kdsl(scene.wp):
                        blowup = diagnose_blowup(scene, case.dt, case.steps)
                    elif not finite:
                        blowup = "non-finite state"
                    else:
                        blowup = "the error is not finite"
            out.append(ExtremeResult(case.label, case.integrator, prec, case.dt, case.steps, error,
                                     r.extra, blowup))  # fmt: skip
    return out
