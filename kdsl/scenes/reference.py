"""A float64, small-step reference for scenes without a closed form (cloth, nbody).

The reference is the same scene file run in float64 with RK4 at a step far below the
one measured (``min(dt / REF_DIVISOR, REF_OMEGA_STEP / omega_max)``, ``omega_max``
the scene's fastest frequency), through the same ``wp`` binding and device, landing
exactly on ``t``. Results are cached per scene parameters and ``t``, so a sweep pays
for each end time once. The forces it integrates are checked independently: a
scene's host-side energy stays constant along them (``tests/scenes``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

#: The reference step is at most the measured dt over this.
REF_DIVISOR = 8
#: ...and at most this over the fastest frequency (RK4's error per step ~ (h omega)^5).
REF_OMEGA_STEP = 0.1
#: Reference runs longer than this many steps are refused (a clear error, not an hour's wait).
REF_MAX_STEPS = 2_000_000

_CACHE: dict[tuple, tuple[np.ndarray, Any]] = {}


def reference_steps(t: float, dt: float, omega_max: float) -> int:
    """How many RK4 steps the reference takes to reach ``t``."""
    h = min(dt / REF_DIVISOR, REF_OMEGA_STEP / omega_max if omega_max > 0 else math.inf)
    return max(1, math.ceil(t / h - 1e-9))


def small_step_reference(scene: Any, t: float, dt: float) -> np.ndarray:
    """``x(t)`` of ``scene``'s twin in float64 with RK4 at a small step (cached)."""
    return small_step_reference_state(scene, t, dt)[0]


def small_step_reference_state(scene: Any, t: float, dt: float) -> tuple[np.ndarray, Any]:
    """``(x(t), v(t))`` of ``scene``'s twin in float64 with RK4 at a small step (cached)."""
    from kdsl.scenes.binding import SceneError

    if t == 0.0:
        return scene.initial_state()
    steps = reference_steps(t, dt, scene.omega_max())
    if steps > REF_MAX_STEPS:
        raise SceneError(f"scene {scene.name!r}: the float64 reference would take {steps} RK4 "
                         f"steps (omega_max {scene.omega_max():.3g}); shorten the run")  # fmt: skip
    key = (scene.name, scene.wp.__name__, scene.device, tuple(sorted(scene.params.items())),
           round(t, 12), steps)  # fmt: skip
    ref = _CACHE.get(key)
    if ref is None:
        backend = scene.launch_options.get("backend")
        twin = type(scene)(scene.wp, "f64", "rk4", device=scene.device, backend=backend,
                           **scene.params)  # fmt: skip
        h = t / steps
        for _ in range(steps):
            twin.step(h)
        ref = _CACHE[key] = twin.state()
    return ref
