"""NumPy: from_numpy, the dtype helpers, __array_interface__ and NumPy launch arguments."""

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslError, KdslLaunchError, KdslTypeError


@wp.kernel
def scale(x: wp.array(dtype=float), s: float):
    i = wp.tid()
    x[i] = x[i] * s


@wp.kernel
def scale_vec(v: wp.array(dtype=wp.vec3), s: float):
    i = wp.tid()
    v[i] = v[i] * s


def test_from_numpy_copies_and_infers_the_dtype():
    src = np.arange(4, dtype=np.float64)
    a = wp.from_numpy(src)
    assert a.dtype is wp.float64 and a.shape == (4,)
    src[0] = 7.0
    assert a.numpy()[0] == 0.0  # a copy, as the seed describes


def test_from_numpy_vector_dtype_takes_trailing_dims():
    a = wp.from_numpy(np.arange(12, dtype=np.float32).reshape(4, 3), dtype=wp.vec3)
    assert a.shape == (4,) and a.dtype is wp.vec3
    with pytest.raises(KdslError, match="last dims must be"):
        wp.from_numpy(np.zeros((4, 2), np.float32), dtype=wp.vec3)


@pytest.mark.parametrize(
    "dtype, np_dtype",
    [(wp.float32, np.float32), (wp.float16, np.float16), (wp.int64, np.int64),
     (wp.uint8, np.uint8), (wp.bool, np.bool_), (float, np.float32), (wp.vec3d, np.float64)],
)  # fmt: skip
def test_dtype_to_numpy(dtype, np_dtype):
    assert wp.dtype_to_numpy(dtype) == np.dtype(np_dtype)


@pytest.mark.parametrize(
    "np_dtype, dtype",
    [(np.float32, wp.float32), (np.dtype("float64"), wp.float64), (np.int8, wp.int8),
     (np.uint64, wp.uint64), (np.bool_, wp.bool)],
)  # fmt: skip
def test_dtype_from_numpy(np_dtype, dtype):
    assert wp.dtype_from_numpy(np_dtype) is dtype


def test_dtype_from_numpy_rejects_complex():
    with pytest.raises(KdslTypeError, match="complex64 has no kdsl equivalent"):
        wp.dtype_from_numpy(np.complex64)


def test_array_interface_is_zero_copy_both_ways():
    a = wp.zeros(3, dtype=wp.vec3)
    n = np.asarray(a)
    assert n.shape == (3, 3) and n.ctypes.data == a.ptr
    n[1] = 5.0
    assert a.numpy()[1].tolist() == [5.0, 5.0, 5.0]
    assert np.array(wp.array([1.0, 2.0, 3.0], dtype=float)).tolist() == [1.0, 2.0, 3.0]


def test_numpy_arrays_launch_directly_zero_copy():
    x = np.arange(4, dtype=np.float32)
    wp.launch(scale, dim=4, inputs=[x, 2.0])
    assert x.tolist() == [0.0, 2.0, 4.0, 6.0]
    v = np.ones((2, 3), np.float32)
    wp.launch(scale_vec, dim=2, inputs=[v, 3.0])
    assert (v == 3.0).all()


def test_numpy_launch_mismatch_messages():
    with pytest.raises(KdslLaunchError, match=r"got a NumPy float64 array; convert it with"):
        wp.launch(scale, dim=4, inputs=[np.zeros(4), 1.0])
    with pytest.raises(KdslLaunchError, match=r"expected a 1-d array of vec<3, f32>"):
        wp.launch(scale_vec, dim=4, inputs=[np.zeros((4, 2), np.float32), 1.0])
