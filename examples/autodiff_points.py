"""Minimize a loss over 2D points with a Tape and plain NumPy gradient descent.

    python examples/autodiff_points.py

The loss kernel is the one of the Warp PyTorch examples,
``total = sum_i (x_i0^2 + x_i1^2)``, accumulated with ``atomic_add``. It is recorded on
a tape once; each step zeroes the gradients, replays the tape backwards, and
moves the points against their gradient with NumPy (the Warp example uses
PyTorch's Adam; any optimizer that reads ``xs.grad`` works the same way).
"""

import numpy as np

import kdsl as wp


@wp.kernel
def loss(xs: wp.array(dtype=float, ndim=2), total: wp.array(dtype=float)):
    tid = wp.tid()
    wp.atomic_add(total, 0, xs[tid, 0] ** 2.0 + xs[tid, 1] ** 2.0)


def optimize(
    n: int = 100, steps: int = 50, lr: float = 0.1, device: str = "cpu", verbose: bool = True
) -> tuple[np.ndarray, list[float]]:
    """Run ``steps`` of gradient descent; returns the final points and the loss history."""
    rng = np.random.default_rng(42)
    xs = wp.array(rng.normal(size=(n, 2)), dtype=wp.float32, device=device, requires_grad=True)
    total = wp.zeros(1, dtype=wp.float32, device=device, requires_grad=True)

    tape = wp.Tape()
    with tape:
        wp.launch(loss, dim=len(xs), inputs=[xs], outputs=[total], device=device)

    history = [float(total.numpy()[0])]
    for i in range(steps):
        tape.zero()
        tape.backward(loss=total)  # xs.grad = dl/dxs = 2 xs
        xs.assign(xs.numpy() - lr * xs.grad.numpy())
        # Only to report the loss: the optimization itself needs just the gradient.
        total.zero_()
        wp.launch(loss, dim=len(xs), inputs=[xs], outputs=[total], device=device)
        history.append(float(total.numpy()[0]))
        if verbose and i % 10 == 0:
            print(f"{i}\tloss: {history[-1]:.6f}")
    return xs.numpy(), history


def main() -> int:
    """Optimize and check that every step shrinks the loss by (1 - 2 lr)^2."""
    points, history = optimize()
    ratios = np.array(history[1:]) / np.array(history[:-1])
    print(f"final loss {history[-1]:.3e}, mean |x| {np.abs(points).mean():.3e}")
    return 0 if np.allclose(ratios, (1 - 2 * 0.1) ** 2, rtol=1e-3) else 1


if __name__ == "__main__":
    raise SystemExit(main())
