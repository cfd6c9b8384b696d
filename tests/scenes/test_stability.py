"""The measured stability limits agree with theory within 10%; blow-ups are diagnosed."""

import math

import pytest

from kdsl.scenes.measure import diagnose_blowup, make_scene, stability, stable_dt


def _limit(scene, dt0):
    dt, bound, _ = stable_dt(scene, 2000, dt0)
    assert bound == "measured"
    return dt


def test_symplectic_euler_on_a_linear_spring_stops_at_2_over_omega():
    scene = make_scene("chain", "f64", "symplectic_euler", count=1, stiffness=100.0)
    omega = math.sqrt(2 * 100.0)  # one unit mass between two springs
    assert _limit(scene, 0.01) == pytest.approx(2 / omega, rel=0.1)


def test_explicit_euler_on_a_damped_spring_stops_at_c_over_omega_squared():
    scene = make_scene("chain", "f64", "explicit_euler", count=1, stiffness=100.0, damping=10.0)
    assert _limit(scene, 0.01) == pytest.approx(10.0 / 200.0, rel=0.1)
    assert scene.theory_dt_limit("explicit_euler") == pytest.approx(10.0 / 200.0)


def test_heat_explicit_limit_is_h2_over_4d():
    scene = make_scene("heat", "f64", "explicit_euler", grid=8)
    assert _limit(scene, 1e-3) == pytest.approx(scene.textbook_dt_limit(), rel=0.1)


def test_wave_leapfrog_obeys_the_cfl_limit():
    scene = make_scene("wave", "f64", "symplectic_euler", grid=8)
    assert _limit(scene, 1e-2) == pytest.approx(scene.cfl_dt_limit(), rel=0.1)


def test_implicit_euler_is_stable_at_every_dt_tried():
    scene = make_scene("heat", "f64", "backward_euler", grid=4)
    dt, bound, _ = stable_dt(scene, 50, 1e-2, span=100.0)
    assert bound == "above" and dt >= 0.5


def test_blowup_names_the_step_and_kernel():
    scene = make_scene("chain", "f32", "symplectic_euler", count=1)
    report = diagnose_blowup(scene, 1.0, 500)
    assert report.startswith("step "), report
    assert "NaN" in report or "Inf" in report, report


def test_stability_table_reports_theory_and_drift():
    (r,) = stability("chain", ["symplectic_euler"], ["f32"], 300, 200, 0.01, count=1)
    assert r.bound == "measured" and r.theory == pytest.approx(2 / math.sqrt(200))
    assert r.drift is not None and abs(r.drift) < 0.2
