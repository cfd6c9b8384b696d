"""Each scene's error shrinks with dt at its integrator's order (loose bounds)."""

import math

import pytest

from kdsl.scenes.base import ORDER
from kdsl.scenes.measure import make_scene, run_scene

#: scene -> (small parameters, dt, end time)
CASES = {
    "particles": ({"count": 8}, 0.02, 1.0),
    "chain": ({"count": 4, "damping": 0.5}, 0.004, 0.4),
    "heat": ({"grid": 8}, 4e-4, 0.02),
    "wave": ({"grid": 8}, 8e-3, 0.4),
    "nbody": ({"count": 8}, 8e-3, 0.16),  # the energy error
    "cloth": ({"grid": 3, "gap": 1.0}, 4e-4, 0.02),  # no contact: smooth forces
}


def _error(scene_name, integrator, dt, t_end, backend="cpu"):
    params, _, _ = CASES[scene_name]
    scene = make_scene(scene_name, "f64", integrator, backend, **params)
    return run_scene(scene, dt, round(t_end / dt), backend).error


def _cases():
    from kdsl.scenes import scene_class

    for name in CASES:
        for integ in scene_class(name).integrators:
            yield name, integ


@pytest.mark.parametrize(("scene_name", "integrator"), list(_cases()))
def test_error_shrinks_at_the_expected_order(scene_name, integrator):
    _, dt, t_end = CASES[scene_name]
    coarse = _error(scene_name, integrator, dt, t_end)
    fine = _error(scene_name, integrator, dt / 2, t_end)
    observed = math.log2(coarse / fine)
    assert observed > ORDER[integrator] - 0.4, (coarse, fine, observed)
    assert observed < ORDER[integrator] + 1.0, (coarse, fine, observed)


def test_interp_backend_runs_a_scene_like_cpu():
    cpu = _error("particles", "rk4", 0.1, 0.4, "cpu")
    interp = _error("particles", "rk4", 0.1, 0.4, "interp")
    assert interp == pytest.approx(cpu, rel=1e-6)
    assert cpu < 1e-5


def test_low_precision_error_is_larger_than_f64():
    errs = {}
    for prec in ("f16", "f32", "f64"):
        scene = make_scene("chain", prec, "rk4", count=4)
        errs[prec] = run_scene(scene, 1e-3, 100).error
    assert errs["f64"] < errs["f32"] < errs["f16"] < 0.1
