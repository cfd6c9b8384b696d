"""A kdsl kernel as a PyTorch custom operator, inside ``torch.compile(fullgraph=True)``.

    python examples/autodiff_torch_compile.py

``torch.library.custom_op`` makes the kdsl launches opaque to the compiler, so a
graph that calls them compiles whole. The forward op launches the kernel; the
backward op launches its adjoint (``launch(..., adjoint=True)``); ``register_fake``
tells the compiler the shapes; ``register_autograd`` connects the two. This is
the Warp documentation's Rosenbrock example (PyTorch >= 2.4) with one fix: the
backward returns a fresh gradient array instead of the input's ``.grad`` (which
the adjoint would fill and PyTorch would then add to itself, doubling it).
On the CPU, ``torch.compile`` needs a C++ compiler (Inductor generates C++).
"""

import numpy as np
import torch

import kdsl as wp


@wp.func
def rosenbrock(x: float, y: float):
    return (1.0 - x) ** 2.0 + 100.0 * (y - x**2.0) ** 2.0


@wp.kernel
def eval_rosenbrock(
    xy: wp.array(dtype=wp.vec2),
    # outputs
    z: wp.array(dtype=float),
):
    i = wp.tid()
    v = xy[i]
    z[i] = rosenbrock(v[0], v[1])


@torch.library.custom_op("kdsl_examples::rosenbrock", mutates_args=())
def kdsl_rosenbrock(xy: torch.Tensor, num_points: int) -> torch.Tensor:
    wp_xy = wp.from_torch(xy, dtype=wp.vec2, requires_grad=False)
    wp_z = wp.zeros(num_points, dtype=wp.float32, device=wp_xy.device)
    wp.launch(eval_rosenbrock, dim=num_points, inputs=[wp_xy], outputs=[wp_z], device=wp_xy.device)
    return wp.to_torch(wp_z)


@kdsl_rosenbrock.register_fake
def _(xy, num_points):
    return torch.empty(num_points, dtype=torch.float32, device=xy.device)


@torch.library.custom_op("kdsl_examples::rosenbrock_backward", mutates_args=())
def kdsl_rosenbrock_backward(
    xy: torch.Tensor, num_points: int, z: torch.Tensor, adj_z: torch.Tensor
) -> torch.Tensor:
    wp_xy = wp.from_torch(xy, dtype=wp.vec2, requires_grad=False)
    wp_z = wp.from_torch(z, requires_grad=False)
    wp_adj_z = wp.from_torch(adj_z.contiguous(), requires_grad=False)
    wp_adj_xy = wp.zeros_like(wp_xy)
    wp.launch(
        eval_rosenbrock,
        dim=num_points,
        inputs=[wp_xy],
        outputs=[wp_z],
        adj_inputs=[wp_adj_xy],
        adj_outputs=[wp_adj_z],
        adjoint=True,
        device=wp_xy.device,
    )
    return wp.to_torch(wp_adj_xy)


@kdsl_rosenbrock_backward.register_fake
def _(xy, num_points, z, adj_z):
    return torch.empty_like(xy)


def _backward(ctx, adj_z):
    return kdsl_rosenbrock_backward(ctx.xy, ctx.num_points, ctx.z, adj_z), None


def _setup_context(ctx, inputs, output):
    ctx.xy, ctx.num_points = inputs
    ctx.z = output


kdsl_rosenbrock.register_autograd(_backward, setup_context=_setup_context)


def optimize(
    num_points: int = 1500, steps: int = 2000, lr: float = 5e-2, device: str = "cpu"
) -> np.ndarray:
    """Adam on the points through the compiled graph; returns their mean (minimum (1, 1))."""
    rng = np.random.default_rng(42)
    xy = torch.tensor(
        rng.normal(size=(num_points, 2)), dtype=torch.float32, requires_grad=True, device=device
    )
    opt = torch.optim.Adam([xy], lr=lr)

    @torch.compile(fullgraph=True)
    def forward():
        return kdsl_rosenbrock(xy, num_points)

    for _ in range(steps):
        opt.zero_grad()
        z = forward()
        z.backward(torch.ones_like(z))
        opt.step()
    return np.mean(xy.numpy(force=True), axis=0)


def main() -> int:
    """Optimize; succeed when the points gather at the minimum."""
    mean = optimize()
    print(f"mean of the points {mean} (minimum at (1, 1))")
    return 0 if np.allclose(mean, 1.0, atol=0.1) else 1


if __name__ == "__main__":
    raise SystemExit(main())
