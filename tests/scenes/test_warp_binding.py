"""The same scene files run under NVIDIA Warp (``bind("warp")``)."""

import pytest

from kdsl.scenes.measure import make_scene, run_scene
from tests.warp_peer import import_warp_cpu

warp = import_warp_cpu()


@pytest.mark.parametrize(("name", "params"), [("particles", {"count": 8}), ("heat", {"grid": 4})])
def test_scene_runs_under_warp_like_under_kdsl(name, params):
    errors = {}
    for binding in ("kdsl", "warp"):
        scene = make_scene(name, "f32", "rk4", binding=binding, **params)
        errors[binding] = run_scene(scene, scene.default_dt, 10).error
    assert errors["warp"] < 1e-4
    assert errors["warp"] == pytest.approx(errors["kdsl"], rel=0.5, abs=1e-6)


@pytest.mark.parametrize(
    ("name", "integrator", "params", "dt", "steps"),
    [("stiff_odes", "backward_euler", {"count": 4}, 1e-3, 5),
     ("ocean", "analytic", {"grid": 4}, 1 / 60, 5)],
)  # fmt: skip
def test_new_scenes_run_under_warp_like_under_kdsl(name, integrator, params, dt, steps):
    errors = {}
    for binding in ("kdsl", "warp"):
        scene = make_scene(name, "f32", integrator, binding=binding, **params)
        errors[binding] = run_scene(scene, dt, steps).error
    assert errors["warp"] == pytest.approx(errors["kdsl"], rel=0.5, abs=1e-6)
