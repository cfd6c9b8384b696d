"""All-pairs gravitational n-body simulation with kdsl kernels.

    python examples/nbody.py [--n 128] [--steps 5] [--backend NAME]

Each step computes accelerations with an all-pairs kernel (a loop over every
body, Plummer softening) and integrates with semi-implicit Euler. The total
momentum is printed, which an exact all-pairs sum conserves, and the first
step's accelerations are checked against NumPy.
"""

import argparse
import time

import numpy as np

import kdsl as wp


@wp.kernel
def accelerations(
    pos: wp.array(dtype=wp.vec3),
    mass: wp.array(dtype=float),
    acc: wp.array(dtype=wp.vec3),
    eps2: float,
):
    i = wp.tid()
    p = pos[i]
    a = wp.vec3(0.0, 0.0, 0.0)
    for j in range(pos.shape[0]):
        d = pos[j] - p
        r2 = wp.dot(d, d) + eps2
        inv_r = 1.0 / wp.sqrt(r2)
        a = a + d * (mass[j] * inv_r * inv_r * inv_r)
    acc[i] = a


@wp.kernel
def step(
    pos: wp.array(dtype=wp.vec3),
    vel: wp.array(dtype=wp.vec3),
    acc: wp.array(dtype=wp.vec3),
    dt: float,
):
    i = wp.tid()
    v = vel[i] + acc[i] * dt
    vel[i] = v
    pos[i] = pos[i] + v * dt


def reference_accelerations(pos: np.ndarray, mass: np.ndarray, eps2: float) -> np.ndarray:
    """The same accelerations in NumPy float64."""
    p = pos.astype(np.float64)
    d = p[None, :, :] - p[:, None, :]
    inv_r = 1.0 / np.sqrt(np.sum(d * d, axis=2) + eps2)
    return np.einsum("ijk,ij->ik", d, mass.astype(np.float64)[None, :] * inv_r**3)


def main() -> int:
    """Run the simulation; exit status 1 if the first step disagrees with NumPy."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=128)
    parser.add_argument("--steps", type=int, default=5)
    parser.add_argument("--backend", default=None, help="default: the cpu device's")
    args = parser.parse_args()

    n, eps2, dt = args.n, 0.01, 1e-3
    rng = np.random.default_rng(42)
    pos_np = rng.normal(size=(n, 3)).astype(np.float32)
    mass_np = rng.uniform(0.5, 1.5, n).astype(np.float32)
    pos = wp.from_numpy(pos_np, dtype=wp.vec3, device="cpu")
    vel = wp.zeros(n, dtype=wp.vec3, device="cpu")
    acc = wp.zeros(n, dtype=wp.vec3, device="cpu")
    mass = wp.from_numpy(mass_np, dtype=wp.float32, device="cpu")

    backend = args.backend or wp.default_backend_for("cpu")
    wp.launch(accelerations, dim=n, inputs=[pos, mass, acc, eps2], device="cpu", backend=backend)
    want = reference_accelerations(pos_np, mass_np, eps2)
    err = float(np.max(np.abs(acc.numpy() - want)) / np.max(np.abs(want)))
    print(f"{n} bodies on backend {backend!r}: first-step relative error {err:.2e}")

    start = time.perf_counter()
    for _ in range(args.steps):
        wp.launch(accelerations, dim=n, inputs=[pos, mass, acc, eps2], device="cpu",
                  backend=backend)  # fmt: skip
        wp.launch(step, dim=n, inputs=[pos, vel, acc, dt], device="cpu", backend=backend)
    elapsed = time.perf_counter() - start
    momentum = (vel.numpy().astype(np.float64) * mass_np[:, None]).sum(axis=0)
    print(f"{args.steps} steps in {elapsed:.3f} s; total momentum {momentum} (should stay ~0)")
    return 0 if err < 1e-4 else 1


if __name__ == "__main__":
    raise SystemExit(main())
