"""The scenes beyond the first four: stiff ODEs, throw's gradient, ocean, nbody, cloth."""

import math

import numpy as np
import pytest

from kdsl.scenes.measure import make_scene, run_scene, stable_dt


def _run(name, integrator, dt, steps, precision="f64", **params):
    scene = make_scene(name, precision, integrator, **params)
    return scene, run_scene(scene, dt, steps)


# --------------------------------------------------------------------------- stiff_odes


def test_stiff_odes_implicit_is_stable_and_first_order_where_explicit_blows_up():
    _, coarse = _run("stiff_odes", "backward_euler", 2e-3, 25, count=4)
    _, fine = _run("stiff_odes", "backward_euler", 1e-3, 50, count=4)
    assert fine.error < 1e-3
    assert math.log2(coarse.error / fine.error) == pytest.approx(1.0, abs=0.3)
    for integ in ("explicit_euler", "rk4"):
        scene, r = _run("stiff_odes", integ, 1e-3, 20, count=4)
        assert r.error == math.inf, integ  # 2000x past the explicit limit
        assert not np.all(np.isfinite(scene.state()[0]))


def test_stiff_odes_explicit_limit_matches_the_stiffest_eigenvalue():
    scene = make_scene("stiff_odes", "f64", "explicit_euler", count=4)
    dt, bound, _ = stable_dt(scene, 200, 1e-6)
    assert bound == "measured"
    assert dt == pytest.approx(scene.theory_dt_limit("explicit_euler"), rel=0.1)


def test_stiff_odes_reference_is_tight():
    scene = make_scene("stiff_odes", "f64", count=4)
    a, b = scene.reference(0.05), scene.reference(0.05, max_step=1e-4)
    assert np.max(np.abs(a - b) / (np.abs(b) + 1e-12)) < 1e-10
    # Robertson conserves y1 + y2 + y3 = 1.
    assert np.sum(a[1::2], axis=1) == pytest.approx(1.0, abs=1e-12)


def test_stiff_odes_needs_both_systems():
    from kdsl.scenes import SceneError

    with pytest.raises(SceneError, match="count >= 2"):
        make_scene("stiff_odes", "f64", count=1)


@pytest.mark.parametrize(("name", "params", "message"),
                         [("cloth", {"grid": 1}, "cloth needs grid >= 2, not 1"),
                          ("nbody", {"count": 1}, "nbody needs count >= 2, not 1")])  # fmt: skip
def test_scene_size_below_its_minimum_is_a_scene_error(name, params, message):
    from kdsl.scenes import SceneError

    with pytest.raises(SceneError, match=message):
        make_scene(name, "f64", **params)


# --------------------------------------------------------------------------- throw


@pytest.mark.parametrize("integrator", ["symplectic_euler", "velocity_verlet", "backward_euler"])
def test_throw_tape_gradient_matches_float64_finite_differences(integrator):
    scene = make_scene("throw", "f64", integrator, count=4)
    v0 = scene.wp.array(scene.guess, dtype=scene.k.vec3, device=scene.device)
    grad, _ = scene.gradient(v0, 0.05)
    fd = scene.discrete_fd_gradient(0.05)
    assert np.max(np.abs(grad.numpy() - fd)) / np.max(np.abs(fd)) < 1e-8


def test_throw_gradient_error_shrinks_with_dt_and_descent_hits_the_targets():
    _, coarse = _run("throw", "velocity_verlet", 0.04, 1, count=4)
    _, fine = _run("throw", "velocity_verlet", 0.02, 12, count=4)
    assert math.log2(coarse.error / fine.error) == pytest.approx(2.0, abs=0.4)
    assert fine.extra["max miss (m)"] < 0.05  # from metres off at the initial guess


# --------------------------------------------------------------------------- ocean


def test_ocean_float32_loses_the_phase_at_large_times_unless_reduced_on_the_host():
    _, r0 = _run("ocean", "analytic", 1 / 60, 5, "f32", grid=4)
    _, late = _run("ocean", "analytic", 1 / 60, 5, "f32", grid=4, t0=1e5)
    _, fixed = _run("ocean", "analytic", 1 / 60, 5, "f32", grid=4, t0=1e5, host_phase=1)
    _, exact = _run("ocean", "analytic", 1 / 60, 5, "f64", grid=4)
    assert exact.error < 1e-12 and r0.error < 1e-5 and fixed.error < 1e-5
    assert late.error > 100 * fixed.error


# --------------------------------------------------------------------------- nbody, cloth


def test_nbody_conserves_momentum_and_scale_changes_nothing_in_f64():
    _, r = _run("nbody", "velocity_verlet", 4e-3, 20, count=8)
    assert r.extra["momentum error"] < 1e-12
    for scale in (1e-6, 1e6):
        _, rs = _run("nbody", "velocity_verlet", 4e-3, 20, count=8, scale=scale)
        assert rs.error == pytest.approx(r.error, rel=1e-6)


def test_cloth_forces_conserve_the_host_energy_through_contact():
    scene, r = _run("cloth", "velocity_verlet", 2e-4, 250, grid=3, stiffness=1e2, gap=0.0)
    assert np.min(scene.state()[0][:, 1]) < scene.center[1] + scene.radius  # it touched
    assert abs(r.energy_drift) < 1e-4


def test_stiff_cloth_backward_euler_stays_bounded_where_symplectic_euler_blows_up():
    params = {"grid": 3, "stiffness": 1e6, "gap": 1.0}
    scene = make_scene("cloth", "f64", "symplectic_euler", **params)
    for _ in range(50):
        scene.step(1e-3)
    assert not np.all(np.isfinite(scene.state()[1])) or np.max(np.abs(scene.state()[1])) > 1e3
    scene = make_scene("cloth", "f64", "backward_euler", **params)
    for _ in range(50):
        scene.step(1e-3)
    assert np.max(np.abs(scene.state()[1])) < 10.0


def test_degenerate_cloth_runs_finite():
    scene, r = _run("cloth", "symplectic_euler", 2e-4, 20, "f32", grid=3, degenerate=1)
    assert np.all(np.isfinite(scene.state()[0])) and r.error < 1e-3
