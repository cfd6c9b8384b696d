"""Two first kdsl kernels on the CPU: saxpy and a particle integration step.

    python examples/saxpy.py

Each kernel runs with the default backend for the ``cpu`` device and is checked
against the same computation in NumPy. ``kdsl ir examples/saxpy.py:saxpy`` prints
the IR the compiler made of it.
"""

import numpy as np

import kdsl as wp


@wp.kernel
def saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
    i = wp.tid()
    y[i] = a * x[i] + y[i]


@wp.kernel
def integrate(
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    f: wp.array(dtype=wp.vec3),
    w: wp.array(dtype=float),
    gravity: wp.vec3,
    dt: float,
):
    # Semi-implicit Euler step for particle tid.
    tid = wp.tid()
    v1 = v[tid] + (f[tid] * w[tid] + gravity) * dt
    x[tid] = x[tid] + v1 * dt
    v[tid] = v1


def run_saxpy(n: int = 1024) -> float:
    """y = 2x + y on n elements; returns the largest error against NumPy."""
    x_np = np.arange(n, dtype=np.float32)
    y_np = np.ones(n, dtype=np.float32)
    x = wp.from_numpy(x_np, dtype=wp.float32, device="cpu")
    y = wp.from_numpy(y_np, dtype=wp.float32, device="cpu")
    wp.launch(saxpy, dim=n, inputs=[x, y, 2.0], device="cpu")
    got = y.numpy()
    print(f"saxpy:     y[:5] = {got[:5]}")
    return float(np.max(np.abs(got - (2.0 * x_np + y_np))))


def run_integrate(n: int = 256, steps: int = 10, dt: float = 0.01) -> float:
    """``steps`` integration steps of n particles; returns the largest position error."""
    rng = np.random.default_rng(0)
    x_np = rng.uniform(-1, 1, (n, 3)).astype(np.float32)
    v_np = np.zeros((n, 3), np.float32)
    f_np = rng.uniform(-1, 1, (n, 3)).astype(np.float32)
    w_np = rng.uniform(0.5, 2.0, n).astype(np.float32)
    gravity = np.array([0.0, -9.8, 0.0], np.float32)

    x = wp.from_numpy(x_np, dtype=wp.vec3, device="cpu")
    v = wp.from_numpy(v_np, dtype=wp.vec3, device="cpu")
    f = wp.from_numpy(f_np, dtype=wp.vec3, device="cpu")
    w = wp.from_numpy(w_np, dtype=wp.float32, device="cpu")
    for _ in range(steps):
        wp.launch(integrate, dim=n, inputs=[x, v, f, w, wp.vec3(gravity), dt], device="cpu")

    xr, vr = x_np.astype(np.float64), v_np.astype(np.float64)
    for _ in range(steps):
        vr = vr + (f_np * w_np[:, None] + gravity) * dt
        xr = xr + vr * dt
    got = x.numpy()
    print(f"integrate: x[0] = {got[0]}")
    return float(np.max(np.abs(got - xr)))


def main() -> int:
    """Run both kernels, print results and whether they match NumPy."""
    backend = wp.default_backend_for("cpu")
    print(f"kdsl {wp.__version__}, backend {backend!r} on device 'cpu'")
    errors = {"saxpy": run_saxpy(), "integrate": run_integrate()}
    ok = errors["saxpy"] == 0.0 and errors["integrate"] < 1e-4
    for name, err in errors.items():
        print(f"{name:10s} max |kdsl - numpy| = {err:.3g}")
    print("OK: results match NumPy" if ok else "MISMATCH against NumPy")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
