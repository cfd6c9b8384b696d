"""The Tape example of the Warp introduction: record three launches, then backpropagate.

    python examples/autodiff_tape.py

Forward: ``b = sin(a) * a`` (compute1), ``d = b * c`` (compute2),
``total = sum(d ** 2)`` (loss). ``tape.backward(loss=total)`` replays the adjoints of the
three launches in reverse order; ``tape.gradients[a]`` (the same array as
``a.grad``) then holds d total/da, which is checked against the analytic derivative
and against ``kdsl.autograd.gradcheck``.
"""

import numpy as np

import kdsl as wp


@wp.kernel
def compute1(a: wp.array(dtype=wp.float64), b: wp.array(dtype=wp.float64)):
    i = wp.tid()
    b[i] = wp.sin(a[i]) * a[i]


@wp.kernel
def compute2(
    b: wp.array(dtype=wp.float64), c: wp.array(dtype=wp.float64), d: wp.array(dtype=wp.float64)
):
    i = wp.tid()
    d[i] = b[i] * c[i]


@wp.kernel
def loss(d: wp.array(dtype=wp.float64), total: wp.array(dtype=wp.float64)):
    i = wp.tid()
    wp.atomic_add(total, 0, d[i] * d[i])


def run(a: wp.array, c: wp.array, device: str = "cpu") -> wp.array:
    """Launch the three kernels; returns the loss array (shape (1,), with a gradient)."""
    n = len(a)
    b = wp.zeros(n, dtype=wp.float64, device=device, requires_grad=True)
    d = wp.zeros(n, dtype=wp.float64, device=device, requires_grad=True)
    total = wp.zeros(1, dtype=wp.float64, device=device, requires_grad=True)
    wp.launch(kernel=compute1, dim=n, inputs=[a], outputs=[b], device=device)
    wp.launch(kernel=compute2, dim=n, inputs=[b, c], outputs=[d], device=device)
    wp.launch(kernel=loss, dim=n, inputs=[d], outputs=[total], device=device)
    return total


def forward(a: wp.array, c: wp.array, device: str = "cpu") -> tuple[wp.Tape, wp.array]:
    """``run`` on a new tape; returns the tape and the loss array."""
    tape = wp.Tape()
    with tape:
        total = run(a, c, device)
    return tape, total


def analytic_grads(a: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """d total/da and d total/dc of total = sum((sin(a) a c)^2), in NumPy."""
    b = np.sin(a) * a
    d = b * c
    return 2.0 * d * c * (np.cos(a) * a + np.sin(a)), 2.0 * d * b


def main(n: int = 16, device: str = "cpu") -> float:
    """Backpropagate once; returns the largest error of d total/da and d total/dc."""
    rng = np.random.default_rng(0)
    a_np, c_np = rng.uniform(-2, 2, n), rng.uniform(-1, 1, n)
    a = wp.array(a_np, dtype=wp.float64, device=device, requires_grad=True)
    c = wp.array(c_np, dtype=wp.float64, device=device, requires_grad=True)
    tape, total = forward(a, c, device)
    tape.backward(loss=total)
    print(f"loss = {total.numpy()[0]:.6f}")
    print(f"dl/da[:4] = {tape.gradients[a].numpy()[:4]}")
    ga, gc = analytic_grads(a_np, c_np)
    err = max(np.abs(a.grad.numpy() - ga).max(), np.abs(c.grad.numpy() - gc).max())
    print(f"largest error against the analytic gradient: {err:.3e}")
    # The same check for one kernel, by kdsl.autograd against finite differences.
    b = wp.zeros(n, dtype=wp.float64, device=device, requires_grad=True)
    wp.autograd.gradcheck(compute1, dim=n, inputs=[a], outputs=[b], eps=1e-6, atol=1e-6)
    return float(err)


if __name__ == "__main__":
    raise SystemExit(0 if main() < 1e-9 else 1)
