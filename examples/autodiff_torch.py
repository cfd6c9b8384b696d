"""kdsl gradients in PyTorch optimizations (the Warp PyTorch interop examples).

    python examples/autodiff_torch.py

1. ``from_torch`` + ``Tape`` + ``torch.optim.Adam``: the arrays share the tensors'
   memory and ``.grad``, so ``tape.backward`` fills ``xs.grad`` for Adam.
2. ``to_torch`` + Adam: the variables live in kdsl; Adam updates them through a
   tensor view whose ``.grad`` is the array's gradient.
3. ``torch.autograd.Function`` whose backward is an adjoint launch
   (``launch(..., adjoint=True, adj_inputs=..., adj_outputs=...)``), minimizing the
   Rosenbrock function.

Unlike the Warp documentation's version of 3, the forward wraps ``xy`` with
``requires_grad=False`` and the backward returns a fresh gradient array: wrapping
``xy`` with ``requires_grad=True`` makes the array's gradient *be* ``xy.grad``, so
the adjoint writes the gradient there and PyTorch then adds the returned (same)
gradient to it once more, doubling it (harmless for Adam, wrong for anything else).
The ``torch.library.custom_op`` version under ``torch.compile`` is in
``autodiff_torch_compile.py``. Everything runs on the CPU; with a GPU, pass
``device="cuda"``.
"""

import numpy as np
import torch

import kdsl as wp


@wp.kernel
def loss(xs: wp.array(dtype=float, ndim=2), total: wp.array(dtype=float)):
    tid = wp.tid()
    wp.atomic_add(total, 0, xs[tid, 0] ** 2.0 + xs[tid, 1] ** 2.0)


def optimize_from_torch(n: int = 100, steps: int = 500, device: str = "cpu") -> list[float]:
    """Example 1: PyTorch owns the variables; returns the loss after each step."""
    torch.manual_seed(0)
    xs = torch.randn(n, 2, requires_grad=True, device=device)
    total = torch.zeros(1, requires_grad=True, device=device)
    opt = torch.optim.Adam([xs], lr=0.1)
    wp_xs = wp.from_torch(xs)
    wp_l = wp.from_torch(total)
    tape = wp.Tape()
    with tape:
        # record the loss function kernel launch on the tape
        wp.launch(loss, dim=len(xs), inputs=[wp_xs], outputs=[wp_l], device=wp_xs.device)
    history = []
    for _ in range(steps):
        tape.zero()
        tape.backward(loss=wp_l)  # now xs.grad holds the gradient computed by kdsl
        opt.step()  # updates xs, and with it wp_xs (same memory)
        # only needed to report the loss; the optimization needs just the gradient
        wp_l.zero_()
        wp.launch(loss, dim=len(xs), inputs=[wp_xs], outputs=[wp_l], device=wp_xs.device)
        history.append(total.item())
    return history


def optimize_to_torch(n: int = 100, steps: int = 500, device: str = "cpu") -> list[float]:
    """Example 2: kdsl owns the variables; Adam sees them through ``to_torch``."""
    rng = np.random.default_rng(0)
    xs = wp.array(rng.normal(size=(n, 2)), dtype=wp.float32, device=device, requires_grad=True)
    total = wp.zeros(1, dtype=wp.float32, device=device, requires_grad=True)
    opt = torch.optim.Adam([wp.to_torch(xs)], lr=0.1)  # its .grad is xs.grad
    tape = wp.Tape()
    with tape:
        wp.launch(loss, dim=len(xs), inputs=[xs], outputs=[total], device=xs.device)
    history = []
    for _ in range(steps):
        tape.zero()
        tape.backward(loss=total)
        opt.step()
        total.zero_()
        wp.launch(loss, dim=len(xs), inputs=[xs], outputs=[total], device=xs.device)
        history.append(float(total.numpy()[0]))
    return history


@wp.func
def rosenbrock(x: float, y: float):
    return (1.0 - x) ** 2.0 + 100.0 * (y - x**2.0) ** 2.0


@wp.kernel
def eval_rosenbrock(
    xs: wp.array(dtype=wp.vec2),
    # outputs
    z: wp.array(dtype=float),
):
    i = wp.tid()
    x = xs[i]
    z[i] = rosenbrock(x[0], x[1])


class Rosenbrock(torch.autograd.Function):
    """Example 3: z_i = rosenbrock(xy_i), differentiable by an adjoint launch."""

    @staticmethod
    def forward(ctx, xy, num_points):
        ctx.xy = wp.from_torch(xy, dtype=wp.vec2, requires_grad=False)
        ctx.num_points = num_points
        ctx.z = wp.zeros(num_points, device=ctx.xy.device)  # output
        wp.launch(
            kernel=eval_rosenbrock, dim=num_points, inputs=[ctx.xy], outputs=[ctx.z],
            device=ctx.xy.device,
        )  # fmt: skip
        return wp.to_torch(ctx.z)

    @staticmethod
    def backward(ctx, adj_z):
        adj_xy = wp.zeros_like(ctx.xy)  # receives the gradient (+=)
        wp.launch(
            kernel=eval_rosenbrock,
            dim=ctx.num_points,
            inputs=[ctx.xy],
            outputs=[ctx.z],
            adj_inputs=[adj_xy],
            adj_outputs=[wp.from_torch(adj_z.contiguous())],  # the incoming gradient
            adjoint=True,
            device=ctx.xy.device,
        )
        return wp.to_torch(adj_xy), None


def rosenbrock_grad(xy: np.ndarray) -> np.ndarray:
    """The analytic gradient of the Rosenbrock function at each point, in NumPy."""
    x, y = xy[:, 0], xy[:, 1]
    return np.stack([-2.0 * (1.0 - x) - 400.0 * x * (y - x**2), 200.0 * (y - x**2)], axis=1)


def optimize_rosenbrock(
    num_points: int = 1500, steps: int = 2000, lr: float = 5e-2, device: str = "cpu"
) -> np.ndarray:
    """Example 3's loop: Adam on the points; returns their mean (the minimum is (1, 1))."""
    rng = np.random.default_rng(42)
    xy = torch.tensor(
        rng.normal(size=(num_points, 2)), dtype=torch.float32, requires_grad=True, device=device
    )
    opt = torch.optim.Adam([xy], lr=lr)
    for _ in range(steps):
        opt.zero_grad()
        z = Rosenbrock.apply(xy, num_points)
        z.backward(torch.ones_like(z))
        opt.step()
    return np.mean(xy.numpy(force=True), axis=0)


def main() -> int:
    """Run the three examples; succeed when each one converges."""
    a, b = optimize_from_torch(), optimize_to_torch()
    print(f"from_torch: loss {a[0]:.3f} -> {a[-1]:.3e}")
    print(f"to_torch:   loss {b[0]:.3f} -> {b[-1]:.3e}")
    mean = optimize_rosenbrock()
    print(f"Rosenbrock: mean of the points {mean} (minimum at (1, 1))")
    converged = a[-1] < 1e-3 * a[0] and b[-1] < 1e-3 * b[0]
    return 0 if converged and np.allclose(mean, 1.0, atol=0.1) else 1


if __name__ == "__main__":
    raise SystemExit(main())
