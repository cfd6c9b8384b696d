"""Comparing scalars of different types, as Warp's C comparisons allow (``d < radius``
with ``d: float`` and ``radius: int``, Warp's core/example_fluid); the rule is in
``kdsl/frontend/comparisons.py``."""

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslTypeError

BACKENDS = ["interp", "cpu"]
cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")


@wp.kernel
def _mixed(
    f: wp.array(dtype=float),
    i: wp.array(dtype=int),
    u: wp.array(dtype=wp.uint32),
    d: wp.array(dtype=wp.float64),
    radius: int,
    out: wp.array(dtype=int),
):
    t = wp.tid()
    r = 0
    if f[t] < i[t]:  # the int converts to f32
        r += 1
    if i[t] < u[t]:  # compared by value in int64: -1 < 1u
        r += 2
    if d[t] >= f[t]:  # the f32 widens to f64
        r += 4
    if f[t] == radius:
        r += 8
    if wp.int8(i[t]) != wp.int64(i[t]):
        r += 16
    out[t] = r


def _run(backend, device):
    f = wp.array([0.5, 3.0, 2.0], dtype=float, device=device)
    i = wp.array([1, -1, 2], dtype=int, device=device)
    u = wp.array([1, 1, 1], dtype=wp.uint32, device=device)
    d = wp.array([0.5, 1.0, 2.5], dtype=wp.float64, device=device)
    out = wp.zeros(3, dtype=int, device=device)
    wp.launch(_mixed, 3, [f, i, u, d, 2, out], device=device, backend=backend)
    np.testing.assert_array_equal(out.numpy(), [1 + 4, 2, 4 + 8])


@pytest.mark.parametrize("backend", BACKENDS)
def test_mixed_scalar_comparisons(backend):
    _run(backend, "cpu")


@cuda
def test_mixed_scalar_comparisons_cuda():
    _run("cuda", "cuda:0")


def _compile(fn):
    k = wp.kernel(fn)
    k.build_module()


def test_bool_against_number_is_an_error():
    def k(a: wp.array(dtype=int), b: bool):
        if a[0] == b:
            a[0] = 1

    with pytest.raises(KdslTypeError, match="cannot compare i32 and bool") as e:
        _compile(k)
    assert "test_mixed_comparisons.py" in str(e.value)


def test_uint64_against_signed_is_an_error():
    def k(a: wp.array(dtype=wp.uint64), b: int):
        if a[0] < b:
            a[0] = wp.uint64(1)

    with pytest.raises(KdslTypeError, match="no integer type holds every value"):
        _compile(k)
