"""End to end: seed kernels written with @kdsl.kernel, run on interp, checked with NumPy."""

import numpy as np
import pytest

import kdsl as wp

if not hasattr(wp, "kernel"):  # the frontend lands separately
    pytest.skip("kdsl.kernel is not available", allow_module_level=True)


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
    tid = wp.tid()
    x0 = x[tid]
    v0 = v[tid]
    f0 = f[tid]
    inv_mass = w[tid]
    v1 = v0 + (f0 * inv_mass + gravity) * dt
    x1 = x0 + v1 * dt
    x[tid] = x1
    v[tid] = v1


@wp.kernel
def matmul(a: wp.array2d(dtype=float), b: wp.array2d(dtype=float), c: wp.array2d(dtype=float)):
    i, j = wp.tid()
    s = 0.0
    for k in range(a.shape[1]):
        s += a[i, k] * b[k, j]
    c[i, j] = s


def test_saxpy():
    n = 16
    x = wp.array(np.linspace(0, 1, n), dtype=float)
    y = wp.ones(n, dtype=float)
    wp.launch(saxpy, dim=n, inputs=[x, y, 2.0])
    np.testing.assert_allclose(y.numpy(), 2 * np.linspace(0, 1, n) + 1, rtol=1e-6)


def test_integrate_particles():
    rng = np.random.default_rng(0)
    n = 8
    x0, v0, f0 = (rng.standard_normal((n, 3)).astype(np.float32) for _ in range(3))
    w0 = rng.random(n).astype(np.float32)
    x, v = wp.from_numpy(x0, dtype=wp.vec3), wp.from_numpy(v0, dtype=wp.vec3)
    f, w = wp.from_numpy(f0, dtype=wp.vec3), wp.from_numpy(w0, dtype=float)
    g, dt = wp.vec3(0.0, -9.8, 0.0), 0.01
    wp.launch(integrate, dim=n, inputs=[x, v, f, w, g, dt])
    v1 = v0 + (f0 * w0[:, None] + np.array([0, -9.8, 0], np.float32)) * np.float32(dt)
    np.testing.assert_allclose(v.numpy(), v1, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(x.numpy(), x0 + v1 * np.float32(dt), rtol=1e-5, atol=1e-6)


def test_matmul_2d_tid():
    rng = np.random.default_rng(1)
    a_np = rng.standard_normal((3, 4)).astype(np.float32)
    b_np = rng.standard_normal((4, 5)).astype(np.float32)
    a, b = wp.array(a_np, dtype=float), wp.array(b_np, dtype=float)
    c = wp.zeros((3, 5), dtype=float)
    wp.launch(matmul, dim=(3, 5), inputs=[a, b, c])
    np.testing.assert_allclose(c.numpy(), a_np @ b_np, rtol=1e-5, atol=1e-5)
    with pytest.raises(wp.KdslLaunchError, match="2-d thread index"):
        wp.launch(matmul, dim=15, inputs=[a, b, c])


def test_out_of_bounds_points_at_the_kernel_source():
    # interp always checks bounds; the cpu backend checks only in debug mode (issue 3).
    x, y = wp.zeros(4), wp.zeros(2)
    with pytest.raises(wp.KdslRuntimeError) as info:
        wp.launch(saxpy, dim=4, inputs=[x, y, 1.0], backend="interp")
    msg = str(info.value)
    assert (
        "in kernel 'saxpy'" in msg
        and "out of bounds" in msg
        and "test_launch_e2e.py" in msg
        and "y[i]" in msg
    )
    wp.launch(saxpy, dim=2, inputs=[x, y, 1.0], backend="interp")  # still usable
