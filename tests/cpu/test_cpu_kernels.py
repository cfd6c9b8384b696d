"""cpu backend end to end: programs vs NumPy, threaded launches, vector code, stages."""

from __future__ import annotations

import re

import numpy as np
import pytest

import kdsl as wp
from kdsl.backends.cpu import pool
from kdsl.compiler import lower
from kdsl.errors import KdslLaunchError


@wp.kernel
def saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
    i = wp.tid()
    y[i] = a * x[i] + y[i]


@wp.kernel
def integrate(
    x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3), g: wp.vec3, dt: float, steps: int
):
    i = wp.tid()
    p = x[i]
    u = v[i]
    for _ in range(steps):
        u = u + g * dt
        p = p + u * dt
    x[i] = p
    v[i] = u


@wp.kernel
def matmul(a: wp.array2d(dtype=float), b: wp.array2d(dtype=float), c: wp.array2d(dtype=float)):
    i, j = wp.tid()
    s = 0.0
    for k in range(a.shape[1]):
        s = s + a[i, k] * b[k, j]
    c[i, j] = s


@wp.kernel
def count_into(k: wp.array(dtype=wp.int32), counts: wp.array(dtype=wp.int32)):
    i = wp.tid()
    wp.atomic_add(counts, k[i], 1)


@wp.kernel
def index3(out: wp.array3d(dtype=wp.int32)):
    i, j, k = wp.tid()
    out[i, j, k] = (i * 100 + j) * 100 + k


@wp.kernel
def index4(out: wp.array4d(dtype=wp.int32)):
    i, j, k, m = wp.tid()
    out[i, j, k, m] = ((i * 10 + j) * 10 + k) * 10 + m


@wp.kernel
def linear(out: wp.array(dtype=wp.int32)):
    out[wp.tid()] = wp.tid()


@pytest.fixture
def threaded():
    """Four threads and no inline cutoff, so small launches use the pool."""
    old = pool.min_parallel, pool.adaptive
    pool.min_parallel, pool.adaptive = 1, False
    pool.set_num_threads(4)
    yield
    pool.min_parallel, pool.adaptive = old
    pool.set_num_threads(None)


def test_saxpy(cpu_backend) -> None:
    rng = np.random.default_rng(0)
    x = rng.standard_normal(10_001).astype(np.float32)
    y = rng.standard_normal(10_001).astype(np.float32)
    ya = wp.array(y)
    wp.launch(saxpy, dim=len(x), inputs=[wp.array(x), ya, 1.5], backend="cpu")
    np.testing.assert_allclose(ya.numpy(), np.float32(1.5) * x + y, rtol=1e-6)


def test_integrate(cpu_backend, threaded) -> None:
    rng = np.random.default_rng(1)
    x = rng.standard_normal((500, 3)).astype(np.float32)
    v = rng.standard_normal((500, 3)).astype(np.float32)
    xa, va = wp.array(x, dtype=wp.vec3), wp.array(v, dtype=wp.vec3)
    g = wp.vec3(0.0, -9.8, 0.0)
    wp.launch(integrate, dim=500, inputs=[xa, va, g, 0.01, 10], backend="cpu")
    gx, px, ux = np.array([0, -9.8, 0], np.float32), x.copy(), v.copy()
    for _ in range(10):
        ux = ux + gx * np.float32(0.01)
        px = px + ux * np.float32(0.01)
    np.testing.assert_allclose(xa.numpy(), px, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(va.numpy(), ux, rtol=1e-5, atol=1e-6)


def test_matmul(cpu_backend, threaded) -> None:
    rng = np.random.default_rng(2)
    a = rng.standard_normal((37, 19)).astype(np.float32)
    b = rng.standard_normal((19, 23)).astype(np.float32)
    c = wp.zeros((37, 23), dtype=float)
    wp.launch(matmul, dim=(37, 23), inputs=[wp.array(a), wp.array(b), c], backend="cpu")
    np.testing.assert_allclose(c.numpy(), a.astype(np.float64) @ b, rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("dims", [(1000,), (13, 7, 11), (3, 5, 4, 6)])
def test_threaded_indices(cpu_backend, threaded, dims) -> None:
    out = wp.zeros(dims, dtype=wp.int32)
    kernel = {1: linear, 3: index3, 4: index4}[len(dims)]
    wp.launch(kernel, dim=dims, inputs=[out], backend="cpu")
    base = 100 if len(dims) == 3 else 10
    want = np.zeros(dims, dtype=np.int64)
    for g in np.indices(dims):
        want = want * base + g
    np.testing.assert_array_equal(out.numpy(), want)


def test_atomics_across_threads(cpu_backend, threaded) -> None:
    k = np.random.default_rng(3).integers(0, 8, 100_000).astype(np.int32)
    counts = wp.zeros(8, dtype=wp.int32)
    wp.launch(count_into, dim=len(k), inputs=[wp.array(k), counts], backend="cpu")
    np.testing.assert_array_equal(counts.numpy(), np.bincount(k, minlength=8))


def test_strided_array(cpu_backend) -> None:
    y = np.ones(20, dtype=np.float32)
    view = y[::2]
    wp.launch(saxpy, dim=10, inputs=[np.arange(10, dtype=np.float32), view, 2.0], backend="cpu")
    np.testing.assert_array_equal(y[::2], 2 * np.arange(10) + 1)
    np.testing.assert_array_equal(y[1::2], 1)


def test_empty_launch(cpu_backend) -> None:
    out = wp.zeros(1, dtype=wp.int32)
    wp.launch(linear, dim=0, inputs=[out], backend="cpu")
    assert out.numpy()[0] == 0


def test_wrong_tid_rank(cpu_backend) -> None:
    with pytest.raises(KdslLaunchError):
        wp.launch(index3, dim=(4, 4), inputs=[wp.zeros((4, 4, 4), dtype=wp.int32)], backend="cpu")


def test_saxpy_vectorizes(cpu_backend) -> None:
    module = saxpy.build_module()
    ir_text = lower(cpu_backend, module, "llvm-ir")
    assert re.search(r"<(4|8|16) x float>", ir_text), "the thread loop was not vectorized"
    asm = lower(cpu_backend, module, "asm")
    assert re.search(r"\bv?mulps\b|\bvfmadd\w*ps\b", asm)


def test_stages(cpu_backend) -> None:
    module = saxpy.build_module()
    assert cpu_backend.stages() == ["kir", "kir-opt", "llvm-ir-unopt", "llvm-ir", "asm"]
    assert "func.func" in lower(cpu_backend, module, "kir")
    raw = lower(cpu_backend, module, "llvm-ir-unopt")
    assert re.search(r"define void @\"?kdsl_kernel_saxpy", raw)
    assert "llvm" in cpu_backend.version
