"""The seeds' autodiff examples (examples/autodiff_tape.py, examples/autodiff_points.py).

The examples are imported and run with small sizes; their gradients are checked
against analytic values and central finite differences.
"""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

import kdsl as wp

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def load_example(name: str):
    """Import ``examples/<name>.py`` once per process."""
    key = f"kdsl_example_{name}"
    if key not in sys.modules:
        spec = importlib.util.spec_from_file_location(key, EXAMPLES / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules[key] = module
        spec.loader.exec_module(module)
    return sys.modules[key]


@pytest.fixture(scope="module")
def tape_example():
    return load_example("autodiff_tape")


@pytest.fixture(scope="module")
def points_example():
    return load_example("autodiff_points")


def test_tape_example_runs(tape_example, capsys):
    assert tape_example.main(n=8) < 1e-12
    assert "dl/da" in capsys.readouterr().out


def test_tape_example_gradients_match_finite_differences(tape_example):
    rng = np.random.default_rng(1)
    a_np, c_np = rng.uniform(-2, 2, 5), rng.uniform(-1, 1, 5)
    a = wp.array(a_np, dtype=wp.float64, requires_grad=True)
    c = wp.array(c_np, dtype=wp.float64, requires_grad=True)

    ad = wp.autograd.jacobian(tape_example.run, inputs=[a, c])
    fd = wp.autograd.jacobian_fd(tape_example.run, inputs=[a, c], eps=1e-6)
    ga, gc = tape_example.analytic_grads(a_np, c_np)
    np.testing.assert_allclose(ad[0, 0][0], ga, rtol=1e-12)
    np.testing.assert_allclose(ad[1, 0][0], gc, rtol=1e-12)
    np.testing.assert_allclose(fd[0, 0][0], ga, atol=1e-7)
    np.testing.assert_allclose(fd[1, 0][0], gc, atol=1e-7)


def test_tape_gradients_mapping(tape_example):
    a = wp.array([0.5, 1.0], dtype=wp.float64, requires_grad=True)
    c = wp.array([2.0, -1.0], dtype=wp.float64, requires_grad=True)
    tape, total = tape_example.forward(a, c)
    tape.backward(loss=total)
    assert tape.gradients[a] is a.grad
    np.testing.assert_allclose(
        tape.gradients[a].numpy(), tape_example.analytic_grads(a.numpy(), c.numpy())[0]
    )


def test_points_gradient_is_2x(points_example):
    xs = wp.array(np.array([[1.0, -2.0], [0.5, 3.0]]), dtype=wp.float32, requires_grad=True)
    total = wp.zeros(1, dtype=wp.float32, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(points_example.loss, dim=2, inputs=[xs], outputs=[total])
    tape.backward(loss=total)
    np.testing.assert_allclose(xs.grad.numpy(), 2 * xs.numpy())
    assert wp.autograd.gradcheck(
        points_example.loss, 2, [xs], [total], eps=1e-2, atol=1e-2, show_summary=False
    )


def test_points_optimization_converges(points_example):
    points, history = points_example.optimize(n=20, steps=15, verbose=False)
    ratios = np.array(history[1:]) / np.array(history[:-1])
    np.testing.assert_allclose(ratios, 0.64, rtol=1e-4)  # (1 - 2 lr)^2 per step
    assert history[-1] < 1e-2 * history[0] and np.abs(points).max() < 0.1
