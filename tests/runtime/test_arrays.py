"""kdsl.array and its constructors, in Warp's spellings."""

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslError
from kdsl.ir.types import F32, F64, I32, ArrayType, MatrixType, VectorType


def test_seed_array_interface():
    w = wp.array([1.0, 2.0, 3.0], dtype=float, device="cpu")
    a = np.array(w)
    np.testing.assert_array_equal(a, [1, 2, 3])
    assert a.dtype == np.float32 and w.dtype is wp.float32


def test_array_interface_is_zero_copy():
    w = wp.zeros(4)
    view = np.asarray(w)
    assert view.__array_interface__["data"][0] == w.ptr == w.numpy().ctypes.data
    view[1] = 5
    assert w.numpy()[1] == 5
    w.fill_(2)
    assert view[3] == 2


def test_properties():
    a = wp.zeros((3, 4), dtype=wp.vec3, requires_grad=True)
    assert a.shape == (3, 4) and a.ndim == 2 and a.size == 12 and len(a) == 3
    assert a.strides == (4 * 12, 12)
    assert a.device == "cpu" and str(a.device) == "cpu" and a.device.is_cpu
    assert a.dtype is wp.vec3
    assert a.numpy().shape == (3, 4, 3)
    assert a.grad is not None and a.grad.shape == (3, 4) and a.requires_grad
    assert wp.zeros(2).grad is None
    assert a.__kdsl_type__ == ArrayType(VectorType(3, F32), 2)


@pytest.mark.parametrize(
    ("make", "shape"),
    [
        (lambda: wp.zeros(5), (5,)),
        (lambda: wp.zeros(length=5), (5,)),
        (lambda: wp.zeros((2, 3)), (2, 3)),
        (lambda: wp.zeros(shape=[2, 3, 4]), (2, 3, 4)),
        (lambda: wp.empty(length=4, dtype=wp.vec3), (4,)),
        (lambda: wp.empty((1, 2, 3, 4)), (1, 2, 3, 4)),
        (lambda: wp.ones(3, dtype=int), (3,)),
        (lambda: wp.full(8, 1.23, dtype=float), (8,)),
        (lambda: wp.array(shape=(2, 2), dtype=float), (2, 2)),
        (lambda: wp.array(dtype=float), (0,)),
    ],
)
def test_constructor_shapes(make, shape):
    assert make().shape == shape


def test_constructor_values():
    np.testing.assert_array_equal(wp.zeros(3).numpy(), 0)
    np.testing.assert_array_equal(wp.ones(3, dtype=int).numpy(), 1)
    assert wp.ones(3, dtype=int).dtype is wp.int32
    f = wp.full(8, 1.23, dtype=float)
    np.testing.assert_allclose(f.numpy(), np.float32(1.23))
    v = wp.full(2, wp.vec3(1, 2, 3))
    assert v.dtype is wp.vec3 and v.numpy().tolist() == [[1, 2, 3]] * 2
    assert wp.full(2, 7).dtype is wp.int32
    assert wp.full(2, (1.0, 2.0)).dtype is wp.vec2
    q = wp.zeros(length=2, dtype=wp.quat)
    assert q.numpy().shape == (2, 4)


def test_like_constructors_and_clone():
    src = wp.array(np.arange(6).reshape(2, 3), dtype=wp.float64)
    for out in (wp.zeros_like(src), wp.ones_like(src), wp.empty_like(src), wp.full_like(src, 4)):
        assert out.shape == (2, 3) and out.dtype is wp.float64
    assert wp.full_like(src, 4).numpy()[1, 2] == 4
    c = wp.clone(src)
    np.testing.assert_array_equal(c.numpy(), src.numpy())
    c.fill_(0)
    assert src.numpy()[1, 2] == 5
    d = src.copy()
    assert d.ptr != src.ptr and d.numpy()[1, 1] == 4


def test_slices_are_views():
    arr = wp.zeros(8)
    arr[:4].fill_(1.23)
    np.testing.assert_allclose(arr.numpy(), [1.23] * 4 + [0] * 4, rtol=1e-6)
    arr[4:].fill(2.0)
    assert arr.numpy()[7] == 2
    m = wp.zeros((3, 4))
    row = m[1]
    assert isinstance(row, wp.array) and row.shape == (4,)
    row.fill_(3)
    m[..., 0].fill_(9)
    assert m.numpy()[1].tolist() == [9, 3, 3, 3] and m.numpy()[0, 0] == 9
    assert m[1, 2] == 3 and m[::2].shape == (2, 4) and m[::2].strides == (32, 4)
    with pytest.raises(IndexError):
        m[1, 2, 0]


def test_vector_array_indexing_and_list():
    v = wp.array([[1, 2, 3], [4, 5, 6]], dtype=wp.vec3)
    assert v.shape == (2,)
    e = v[1]
    assert isinstance(e, wp.vec3) and e.tolist() == [4, 5, 6]
    e[0] = 100  # an element read is a copy
    assert v.numpy()[1, 0] == 4
    v[0] = (7, 8, 9)
    assert [x.tolist() for x in v.list()] == [[7, 8, 9], [4, 5, 6]]
    assert wp.array([1.5, 2.5], dtype=float).list() == [1.5, 2.5]


def test_from_numpy_infers_vectors_from_inner_dims():
    data = np.arange(12, dtype=np.float32).reshape(4, 3)
    a = wp.from_numpy(data, dtype=wp.vec3)
    assert a.shape == (4,) and a.dtype is wp.vec3
    data[0, 0] = 99
    assert a.numpy()[0, 0] == 0  # from_numpy copies
    m = wp.from_numpy(np.zeros((2, 3, 3)), dtype=wp.mat33)
    assert m.shape == (2,) and m.__kdsl_type__.dtype == MatrixType(3, 3, F32)
    assert wp.from_numpy(np.zeros(3)).dtype is wp.float64
    assert wp.from_numpy(np.zeros((2, 3), np.int32)).__kdsl_type__ == ArrayType(I32, 2)
    with pytest.raises(KdslError, match="last dims must be \\(3,\\)"):
        wp.from_numpy(np.zeros((4, 2)), dtype=wp.vec3)


def test_one_composite_value_makes_a_one_element_array_as_in_warp():
    # Warp's optim/example_diffray: wp.array(np.array(rot), dtype=wp.quat)
    q = wp.array(np.array([0.0, 0.0, 0.0, 1.0]), dtype=wp.quat)
    assert q.shape == (1,) and q.numpy().tolist() == [[0, 0, 0, 1]]
    assert wp.array(np.eye(3), dtype=wp.mat33).shape == (1,)
    assert wp.array(wp.vec3(1, 2, 3), dtype=wp.vec3, ndim=1).shape == (1,)
    for scalar in (3.0, np.float32(3.0)):
        with pytest.raises(KdslError, match=r"not the scalar (np.float32\()?3.0\)?; write array"):
            wp.array(scalar, dtype=float)


def test_array_from_numpy_without_copy_shares_memory():
    data = np.zeros(3, np.float32)
    a = wp.array(data, dtype=float, copy=False)
    a.fill_(1)
    assert data[0] == 1
    b = wp.array(data, dtype=float)
    b.fill_(2)
    assert data[0] == 1


def test_data_with_shape_and_ndim():
    a = wp.array(np.arange(6), dtype=float, shape=(2, 3))
    assert a.shape == (2, 3) and a.dtype is wp.float32
    with pytest.raises(KdslError, match="does not fill shape"):
        wp.array(np.arange(5), dtype=float, shape=(2, 3))
    with pytest.raises(KdslError, match="ndim=2"):
        wp.array([1.0, 2.0], dtype=float, ndim=2)


def test_annotations():
    assert wp.array(dtype=wp.vec3).__kdsl_type__ == ArrayType(VectorType(3, F32), 1)
    assert wp.array(dtype=float, ndim=2).__kdsl_type__ == ArrayType(F32, 2)
    assert wp.array2d(dtype=float).__kdsl_type__ == ArrayType(F32, 2)
    assert wp.array3d(dtype=wp.float64).__kdsl_type__ == ArrayType(F64, 3)
    assert wp.array4d(dtype=int).__kdsl_type__ == ArrayType(I32, 4)
    assert wp.array1d(dtype=float).__kdsl_type__ == ArrayType(F32, 1)
    assert wp.type_of(wp.array(dtype=wp.mat33)) == ArrayType(MatrixType(3, 3, F32), 1)
    with pytest.raises(TypeError, match="generic"):
        wp.type_of(wp.array())
    assert wp.array2d(np.zeros((2, 2), np.float32), dtype=float).shape == (2, 2)


def test_assign_copy_and_offsets():
    a = wp.zeros(4)
    a.assign([1, 2, 3, 4])
    b = wp.zeros(4)
    b.assign(a)
    np.testing.assert_array_equal(b.numpy(), [1, 2, 3, 4])
    c = wp.zeros(6)
    wp.copy(c, a, dest_offset=2, src_offset=1, count=2)
    np.testing.assert_array_equal(c.numpy(), [0, 0, 2, 3, 0, 0])
    wp.copy(c, a)
    np.testing.assert_array_equal(c.numpy(), [1, 2, 3, 4, 0, 0])
    strided = wp.zeros((2, 4))[:, ::2]
    wp.copy(strided, a)
    np.testing.assert_array_equal(strided.numpy(), [[1, 2], [3, 4]])
    with pytest.raises(KdslError, match="out of range"):
        wp.copy(a, c)
    with pytest.raises(KdslError, match="one dtype"):
        wp.copy(wp.zeros(2, dtype=int), wp.zeros(2))


def test_devices():
    assert wp.get_device().is_cpu and wp.get_device("cpu") == "cpu"
    # Warp's rule: the first GPU when there is one, else the cpu.
    preferred = "cuda:0" if wp.is_cuda_available() else "cpu"
    assert wp.get_preferred_device() == wp.get_device(preferred)
    a = wp.zeros(2)
    assert a.to("cpu") is a
    with pytest.raises(KdslError, match="unknown device"):
        wp.zeros(2, device="tpu")
    wp.init()
    wp.init()
    wp.context.init()
    wp.synchronize()
    assert isinstance(wp.is_cuda_available(), bool)


def test_repr_and_str():
    a = wp.array([1.0, 2.0], dtype=float)
    assert repr(a) == "array([1., 2.], dtype=float32, device='cpu')"
    assert str(a) == "[1. 2.]"


def test_bad_dtypes_and_shapes():
    with pytest.raises(KdslError, match="not an array dtype"):
        wp.zeros(2, dtype=object())
    with pytest.raises(KdslError, match="1 to 4 dimensions"):
        wp.zeros((1, 1, 1, 1, 1))
    with pytest.raises(KdslError, match="negative"):
        wp.zeros(-1)
    with pytest.raises(TypeError, match="integers and slices"):
        wp.zeros(3)[[0, 1]]
