"""The new scenes give the same error on interp (the IR's oracle), cpu and cuda."""

import pytest

import kdsl
from kdsl.scenes.measure import make_scene, run_scene

#: scene -> (integrator, tiny parameters, dt, steps)
TINY = {
    "stiff_odes": ("backward_euler", {"count": 2}, 1e-3, 3),
    "ocean": ("analytic", {"grid": 2, "waves": 2}, 1 / 60, 3),
    "nbody": ("rk4", {"count": 3}, 4e-3, 3),
    "cloth": ("backward_euler", {"grid": 2, "jacobi_iters": 2}, 2e-4, 2),
    "throw": ("velocity_verlet", {"count": 1}, 0.25, 1),
}
BACKENDS = [
    "interp",
    pytest.param("cuda", marks=pytest.mark.skipif(not kdsl.is_cuda_available(), reason="no cuda")),
]


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("name", list(TINY))
def test_scene_error_agrees_with_cpu(name, backend):
    integrator, params, dt, steps = TINY[name]
    errors = {}
    for b in ("cpu", backend):
        scene = make_scene(name, "f64", integrator, b, **params)
        errors[b] = run_scene(scene, dt, steps, b).error
    assert errors[backend] == pytest.approx(errors["cpu"], rel=1e-6, abs=1e-12)
