"""kdsl.map (Warp's wp.map): functions, builtins and lambdas over broadcast arrays."""

import numpy as np
import pytest

import kdsl as wp

needs_cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")


@wp.func
def _pair(a: float):
    return a, a * 2.0


def _norm2(v):
    return wp.dot(v, v)


def test_lambda_builtin_and_in_place():
    a, b, c = (wp.array(np.array(v, np.float32)) for v in ([1, 2, 3], [4, 5, 6], [7, 8, 9]))
    np.testing.assert_allclose(wp.map(lambda x, y, z: x + 2.0 * y - z, a, b, c).numpy(), [2, 4, 6])
    xs = wp.array(np.array([-1.0, 0.0, 1.0], np.float32))
    assert wp.map(wp.clamp, xs, -0.5, 0.5, out=xs) is xs
    np.testing.assert_allclose(xs.numpy(), [-0.5, 0.0, 0.5])


def test_values_broadcasting_indexed_and_tuple_results():
    tf = wp.transform((1.0, 2.0, 3.0), wp.quat_rpy(0.2, -0.6, 0.1))
    pts = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]], np.float32)
    got = wp.map(wp.transform_point, tf, wp.array(pts, dtype=wp.vec3)).numpy()
    want = [np.array(wp.transform_point(tf, wp.vec3(*p))) for p in pts]
    np.testing.assert_allclose(got, want, rtol=1e-6)
    x = wp.array(np.arange(12, dtype=np.float32).reshape(3, 1, 4))
    y = wp.array(np.arange(20, dtype=np.float32).reshape(5, 4))
    np.testing.assert_allclose(wp.map(wp.add, x, y).numpy(), x.numpy() + y.numpy())
    arr = wp.array(np.arange(10, dtype=np.float32))
    iarr = wp.indexedarray1d(arr, [wp.array([1, 3, 5], dtype=int)])
    np.testing.assert_allclose(wp.map(lambda v: v * 10.0, iarr).numpy(), [10, 30, 50])
    lo, hi = wp.map(_pair, wp.array(np.array([1.0, 2.0], np.float32)))
    np.testing.assert_allclose(lo.numpy(), [1, 2])
    np.testing.assert_allclose(hi.numpy(), [2, 4])
    np.testing.assert_allclose(wp.map(_norm2, wp.array(pts, dtype=wp.vec3)).numpy(), [14, 77])
    k = wp.map(_norm2, wp.array(pts, dtype=wp.vec3), return_kernel=True)
    out = wp.zeros(2, dtype=float)
    wp.launch(k, 2, [wp.array(pts, dtype=wp.vec3), out], backend="interp")
    np.testing.assert_allclose(out.numpy(), [14, 77])


def test_map_errors():
    a = wp.zeros(3, dtype=float)
    with pytest.raises(wp.KdslTypeError, match="at least one input"):
        wp.map(wp.sin, 1.0)
    with pytest.raises(wp.KdslValueError, match="do not broadcast"):
        wp.map(wp.add, a, wp.zeros(4, dtype=float))
    with pytest.raises(wp.KdslValueError, match="shape"):
        wp.map(wp.sin, a, out=wp.zeros(4, dtype=float))
    with pytest.raises(wp.KdslTypeError, match="returns f32"):
        wp.map(wp.sin, a, out=wp.zeros(3, dtype=wp.float64))
    with pytest.raises(wp.KdslTypeError, match="cannot pass"):
        wp.map(wp.add, a, "text")
    with pytest.raises(wp.KdslTypeError, match="Python function"):
        wp.map(42, a)


@needs_cuda
def test_map_on_cuda():
    a = wp.array(np.arange(4, dtype=np.float32), device="cuda:0")
    out = wp.map(lambda x: x * x + 1.0, a)
    assert out.device == wp.get_device("cuda:0")
    np.testing.assert_allclose(out.numpy(), np.arange(4) ** 2 + 1.0)
