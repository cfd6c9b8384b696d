"""kdsl gradients in PyTorch: the seed's four examples (examples/autodiff_torch*.py).

from_torch + Tape + Adam, to_torch + Adam, a torch.autograd.Function whose backward
is an adjoint launch, and a torch.library.custom_op under torch.compile(fullgraph=True).
Gradients are compared with analytic values; optimizations run a few steps.
"""

import importlib
import sys
from pathlib import Path

import numpy as np
import pytest

import kdsl as wp

torch = pytest.importorskip("torch")

EXAMPLES = str(Path(__file__).resolve().parents[2] / "examples")


@pytest.fixture(scope="module", autouse=True)
def _one_torch_thread():
    # These tensors are tiny: torch's thread pool only adds contention with kdsl's.
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def load(name: str):
    if EXAMPLES not in sys.path:
        sys.path.insert(0, EXAMPLES)
    return importlib.import_module(name)


@pytest.fixture(scope="module")
def ex():
    return load("autodiff_torch")


def rosenbrock_grad(xy: np.ndarray) -> np.ndarray:
    x, y = xy[:, 0], xy[:, 1]
    return np.stack([-2.0 * (1.0 - x) - 400.0 * x * (y - x**2), 200.0 * (y - x**2)], axis=1)


def points(n=6, seed=0):
    rng = np.random.default_rng(seed)
    return torch.tensor(rng.normal(size=(n, 2)), dtype=torch.float32, requires_grad=True)


def test_from_torch_tape_fills_the_tensor_grad(ex):
    xs, total = points(), torch.zeros(1, requires_grad=True)
    wp_xs, wp_l = wp.from_torch(xs), wp.from_torch(total)
    tape = wp.Tape()
    with tape:
        wp.launch(ex.loss, dim=len(xs), inputs=[wp_xs], outputs=[wp_l])
    tape.backward(loss=wp_l)
    np.testing.assert_allclose(xs.grad.numpy(), 2 * xs.detach().numpy(), rtol=1e-6)
    assert total.grad.item() == 1.0
    tape.zero()
    assert not xs.grad.any()


def test_from_torch_adam_converges(ex):
    history = ex.optimize_from_torch(n=10, steps=40)
    assert history[-1] < 1e-2 * history[0]


def test_to_torch_adam_converges(ex):
    history = ex.optimize_to_torch(n=10, steps=40)
    assert history[-1] < 1e-2 * history[0]


def test_autograd_function_gradient(ex):
    xy = points()
    z = ex.Rosenbrock.apply(xy, len(xy))
    np.testing.assert_allclose(
        z.detach().numpy(),
        (1 - xy[:, 0].detach().numpy()) ** 2
        + 100 * (xy[:, 1].detach().numpy() - xy[:, 0].detach().numpy() ** 2) ** 2,
        rtol=1e-5,
    )
    weights = torch.arange(1.0, len(xy) + 1)  # a non-uniform incoming gradient
    (z * weights).sum().backward()
    want = rosenbrock_grad(xy.detach().numpy().astype(np.float64)) * weights.numpy()[:, None]
    np.testing.assert_allclose(xy.grad.numpy(), want, rtol=1e-4)


def test_autograd_function_optimizes_like_pure_torch(ex):
    mean = ex.optimize_rosenbrock(num_points=16, steps=30)
    # The same optimization with the Rosenbrock function written in PyTorch.
    rng = np.random.default_rng(42)
    xy = torch.tensor(rng.normal(size=(16, 2)), dtype=torch.float32, requires_grad=True)
    opt = torch.optim.Adam([xy], lr=5e-2)
    for _ in range(30):
        opt.zero_grad()
        z = (1.0 - xy[:, 0]) ** 2 + 100.0 * (xy[:, 1] - xy[:, 0] ** 2) ** 2
        z.backward(torch.ones_like(z))
        opt.step()
    np.testing.assert_allclose(mean, xy.detach().numpy().mean(axis=0), rtol=1e-3, atol=1e-4)


class SeedRosenbrock(torch.autograd.Function):
    """The Warp documentation's version, verbatim: its gradient comes out doubled."""

    @staticmethod
    def forward(ctx, xy, num_points):
        ctx.xy = wp.from_torch(xy, dtype=wp.vec2, requires_grad=True)
        ctx.num_points = num_points
        ctx.z = wp.zeros(num_points, requires_grad=True)
        wp.launch(kernel=load("autodiff_torch").eval_rosenbrock, dim=ctx.num_points,
                  inputs=[ctx.xy], outputs=[ctx.z])  # fmt: skip
        return wp.to_torch(ctx.z)

    @staticmethod
    def backward(ctx, adj_z):
        ctx.z.grad = wp.from_torch(adj_z)
        wp.launch(
            kernel=load("autodiff_torch").eval_rosenbrock, dim=ctx.num_points,
            inputs=[ctx.xy], outputs=[ctx.z], adj_inputs=[ctx.xy.grad],
            adj_outputs=[ctx.z.grad], adjoint=True,
        )  # fmt: skip
        return (wp.to_torch(ctx.xy.grad), None)


def test_seed_autograd_function_doubles_the_gradient():
    """Why examples/autodiff_torch.py differs from the seed: ctx.xy.grad *is* xy.grad,
    so the adjoint writes the gradient there and PyTorch adds the returned alias to it."""
    xy = points()
    z = SeedRosenbrock.apply(xy, len(xy))
    z.backward(torch.ones_like(z))
    want = rosenbrock_grad(xy.detach().numpy().astype(np.float64))
    np.testing.assert_allclose(xy.grad.numpy(), 2 * want, rtol=1e-4)


def test_custom_op_under_torch_compile():
    ex = load("autodiff_torch_compile")
    xy = points(8)
    n = len(xy)
    # aot_eager traces the graph (fake tensors, autograd) as inductor does, minus its C++
    # compile; examples/autodiff_torch_compile.py runs the default (inductor) backend.
    compiled = torch.compile(lambda: ex.kdsl_rosenbrock(xy, n), fullgraph=True, backend="aot_eager")
    z = compiled()
    z.backward(torch.ones_like(z))
    np.testing.assert_allclose(
        xy.grad.numpy(), rosenbrock_grad(xy.detach().numpy().astype(np.float64)), rtol=1e-4
    )
    result = torch.library.opcheck(ex.kdsl_rosenbrock, (xy.detach().requires_grad_(True), n))
    assert set(result.values()) == {"SUCCESS"}
