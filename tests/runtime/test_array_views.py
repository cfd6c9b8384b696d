"""Array views and methods with Warp 1.19's semantics (issue 14, item 4).

Views share memory and carry the same view of ``.grad``; strided views (transposes,
slices with steps) launch as they are on every backend and differentiate through a
``kdsl.Tape``.
"""

import ctypes

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslError

BACKENDS = ["interp", "cpu"]
cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")


def _grid(shape, device="cpu", requires_grad=False):
    data = np.arange(int(np.prod(shape)), dtype=np.float32).reshape(shape)
    return wp.array(data, dtype=float, device=device, requires_grad=requires_grad)


# --- transpose ---------------------------------------------------------------------
def test_transpose_is_a_strided_view_with_a_transposed_grad():
    a = _grid((2, 3), requires_grad=True)
    t = a.transpose()
    assert t.shape == (3, 2) and t.strides == (4, 12) and not t.is_contiguous
    assert t.is_transposed and not a.is_transposed and t.ptr == a.ptr
    np.testing.assert_array_equal(t.numpy(), a.numpy().T)
    t[2, 1] = -1.0  # writes through to a
    assert a.numpy()[1, 2] == -1.0
    assert t.grad.shape == (3, 2) and t.grad.strides == (4, 12) and t.grad.ptr == a.grad.ptr
    assert t.requires_grad
    # Twice transposed is the original layout again.
    tt = t.transpose()
    assert tt.strides == a.strides and not tt.is_transposed and tt.is_contiguous


def test_transpose_with_axes():
    a = _grid((2, 3, 4))
    t = a.transpose((2, 0, 1))
    assert t.shape == (4, 2, 3)
    np.testing.assert_array_equal(t.numpy(), np.transpose(a.numpy(), (2, 0, 1)))
    assert a.transpose([0, 1, 2]).is_contiguous and not a.transpose([0, 1, 2]).is_transposed
    b = wp.zeros(5)
    assert b.transpose() is b  # Warp: a no-op on 1-d arrays
    for bad in [(0, 1), (0, 1, 1), (0, 1, 3), (0.0, 1, 2)]:
        with pytest.raises(KdslError, match="permutation"):
            a.transpose(bad)


def test_transpose_of_vector_arrays_keeps_the_components():
    a = wp.array(np.arange(18, dtype=np.float32).reshape(2, 3, 3), dtype=wp.vec3)
    t = a.transpose()
    assert t.shape == (3, 2) and t.dtype is wp.vec3
    np.testing.assert_array_equal(t.numpy(), np.transpose(a.numpy(), (1, 0, 2)))


# --- reshape, flatten, contiguous --------------------------------------------------
def test_reshape_is_a_view_and_infers_one_dim():
    a = _grid((2, 6), requires_grad=True)
    r = a.reshape((3, -1))
    assert r.shape == (3, 4) and r.ptr == a.ptr and r.grad.shape == (3, 4)
    assert r.grad.ptr == a.grad.ptr
    r[0, 0] = 42.0
    assert a.numpy()[0, 0] == 42.0
    assert a.reshape(12).shape == (12,) and a.reshape([4, 3]).shape == (4, 3)
    with pytest.raises(KdslError, match="only one dimension may be -1"):
        a.reshape((-1, -1))
    with pytest.raises(KdslError, match="cannot reshape"):
        a.reshape((5, -1))
    with pytest.raises(KdslError, match="size 12"):
        a.reshape((5, 2))
    with pytest.raises(KdslError, match="1 to 4 dimensions"):
        a.reshape((1, 1, 1, 2, 6))


def test_reshape_and_flatten_refuse_strided_arrays_as_warp_does():
    t = _grid((2, 3)).transpose()
    with pytest.raises(KdslError, match="contiguous"):
        t.reshape(6)
    with pytest.raises(KdslError, match="contiguous"):
        t.flatten()
    c = t.contiguous()
    assert c.is_contiguous and c.ptr != t.ptr
    np.testing.assert_array_equal(c.flatten().numpy(), t.numpy().ravel())


def test_flatten_and_contiguous_are_views_when_they_can_be():
    a = _grid((3, 4), requires_grad=True)
    f = a.flatten()
    assert f.shape == (12,) and f.ptr == a.ptr and f.grad.ptr == a.grad.ptr
    v = wp.zeros(4)
    assert v.flatten() is v and v.contiguous() is v and a.contiguous() is a


def test_contiguous_copy_is_differentiable_on_a_tape():
    a = _grid((2, 3), requires_grad=True)
    tape = wp.Tape()
    with tape:
        c = a.transpose().contiguous()
    assert c.requires_grad
    c.grad.assign(np.arange(6, dtype=np.float32).reshape(3, 2))
    tape.backward()
    np.testing.assert_array_equal(a.grad.numpy(), np.arange(6).reshape(3, 2).T)


# --- slicing -----------------------------------------------------------------------
def test_slices_with_steps_are_views_with_grad_views():
    a = _grid((4, 6), requires_grad=True)
    s = a[1::2, ::3]
    assert s.shape == (2, 2) and s.strides == (48, 12) and not s.is_contiguous
    assert s.ptr == a.ptr + 24
    np.testing.assert_array_equal(s.numpy(), a.numpy()[1::2, ::3])
    s.fill_(-1.0)
    assert (a.numpy()[1::2, ::3] == -1).all() and a.numpy()[0, 0] == 0
    assert s.grad.strides == s.strides and s.grad.ptr == a.grad.ptr + 24
    row = a[2]
    assert row.shape == (6,) and row.grad.ptr == a.grad.ptr + 48


# --- view(dtype) -------------------------------------------------------------------
def test_view_same_size_reinterprets_bits():
    ai = wp.array([-1, 2], dtype=wp.int32)
    au = ai.view(wp.uint32)
    assert au.dtype is wp.uint32 and au.numpy().tolist() == [2**32 - 1, 2]
    f = wp.array([1.0], dtype=float).view(wp.int32)
    assert f.numpy()[0] == 0x3F800000
    q = wp.ones(3, dtype=wp.vec4).view(wp.quat)
    assert q.dtype is wp.quat and q.shape == (3,)
    m = wp.ones(3, dtype=wp.vec4).view(wp.mat22)
    assert m.numpy().shape == (3, 2, 2)
    rgba = wp.array(np.full((2, 4), 1, np.uint8), dtype=wp.vec4ub)
    assert rgba.view(wp.uint32).numpy().tolist() == [0x01010101] * 2


def test_view_between_vectors_and_scalars_shares_memory():
    v = wp.zeros(4, dtype=wp.vec3, requires_grad=True)
    f = v.view(float)
    assert f.shape == (4, 3) and f.strides == (12, 4) and f.ptr == v.ptr
    f[1, 2] = 5.0
    assert v.numpy()[1, 2] == 5.0
    assert f.grad.shape == (4, 3) and f.grad.ptr == v.grad.ptr
    m = wp.zeros(2, dtype=wp.mat33).view(float)
    assert m.shape == (2, 3, 3)
    s = wp.array(np.arange(8, dtype=np.float32).reshape(2, 4))
    sv = s.view(wp.vec4)
    assert sv.shape == (2,) and sv.dtype is wp.vec4 and list(sv[1]) == [4, 5, 6, 7]
    one = wp.zeros((3, 3), dtype=float).view(wp.mat33)
    assert one.shape == (1,)  # Warp's corner case: one matrix gives a 1-element array


def test_view_errors_follow_warps_size_rules():
    with pytest.raises(KdslError, match="4 bytes, f64 has 8"):
        wp.zeros(3, dtype=wp.vec3).view(wp.float64)
    with pytest.raises(KdslError, match="last dims must be"):
        wp.zeros((4, 3), dtype=float).view(wp.vec4)
    with pytest.raises(KdslError, match="not contiguous"):
        wp.zeros((4, 8), dtype=float)[:, ::2].view(wp.vec4)
    with pytest.raises(KdslError, match="cannot view"):
        wp.zeros(3, dtype=wp.float64).view(wp.int32)


# --- grad, to, assign, list, clone, copy -------------------------------------------
def test_grad_setter_checks_what_warp_checks():
    a = wp.zeros((2, 3))
    a.grad = wp.ones((2, 3))
    assert a.requires_grad and a.grad.numpy().sum() == 6
    a.grad = None
    assert a.grad is None and not a.requires_grad
    with pytest.raises(KdslError, match="shape"):
        a.grad = wp.zeros(6)
    with pytest.raises(KdslError, match="dtype"):
        a.grad = wp.zeros((2, 3), dtype=wp.float64)
    with pytest.raises(KdslError, match="strides"):
        a.grad = wp.zeros((3, 2)).transpose()
    with pytest.raises(KdslError, match="kdsl array"):
        a.grad = np.zeros((2, 3))
    b = wp.array(np.ones(3, np.float32), grad=wp.full(3, 2.0))
    assert b.requires_grad and b.grad.numpy().tolist() == [2, 2, 2]


def test_to_list_assign_clone_and_copy_with_offsets():
    a = _grid((2, 3))
    assert a.to("cpu") is a
    assert a.list() == [0.0, 1.0, 2.0, 3.0, 4.0, 5.0] and isinstance(a.list()[0], float)
    assert a.transpose().list() == [0.0, 3.0, 1.0, 4.0, 2.0, 5.0]
    b = wp.zeros((3, 2))
    b.assign(a.transpose())
    np.testing.assert_array_equal(b.numpy(), a.numpy().T)
    c = wp.clone(a.transpose())
    assert c.is_contiguous and c.ptr != a.ptr
    np.testing.assert_array_equal(c.numpy(), a.numpy().T)
    d = wp.zeros(8)
    wp.copy(d, a.transpose(), dest_offset=2, src_offset=1, count=4)  # row-major elements
    assert d.numpy().tolist() == [0, 0, 3, 1, 4, 2, 0, 0]


def test_array_from_ptr_and_from_ptr():
    host = np.arange(6, dtype=np.float32)
    a = wp.array(ptr=host.ctypes.data, dtype=float, shape=(2, 3), device="cpu")
    assert a.ptr == host.ctypes.data and a.numpy().tolist() == [[0, 1, 2], [3, 4, 5]]
    a[1, 1] = -1.0
    assert host[4] == -1.0
    s = wp.array(ptr=host.ctypes.data, dtype=float, shape=(3,), strides=(8,))
    assert s.numpy().tolist() == [0, 2, -1]
    cell = ctypes.c_size_t(host.ctypes.data)  # Warp's from_ptr reads the address from ptr
    b = wp.from_ptr(ctypes.addressof(cell), 6, dtype=float)
    assert b.shape == (6,) and b.ptr == host.ctypes.data
    v = wp.array(ptr=host.ctypes.data, dtype=wp.vec3, shape=2)
    assert list(v[1]) == [3.0, -1.0, 5.0]
    with pytest.raises(KdslError, match="capacity"):
        wp.array(ptr=host.ctypes.data, dtype=float, shape=7, capacity=24)
    with pytest.raises(KdslError, match="dtype and a shape"):
        wp.array(ptr=host.ctypes.data, dtype=float)
    with pytest.raises(KdslError, match="strides= goes with ptr="):
        wp.array([1.0, 2.0], strides=(4,))
    with pytest.raises(KdslError, match="2 strides for 1"):
        wp.array(ptr=host.ctypes.data, dtype=float, shape=2, strides=(4, 4))
    with pytest.raises(KdslError, match="null pointer"):
        wp.array(ptr=0, dtype=float, shape=2)


# --- indexedarray ------------------------------------------------------------------
def test_indexedarray_methods():
    d = _grid((3, 4))
    ia = wp.indexedarray(d, [wp.array([2, 0], dtype=wp.int32), None])
    assert len(ia) == 2 and not ia.is_contiguous
    np.testing.assert_array_equal(ia.numpy(), d.numpy()[[2, 0]])
    assert ia.list()[:4] == [8.0, 9.0, 10.0, 11.0]
    c = ia.contiguous()
    assert c.shape == (2, 4) and c.is_contiguous
    assert ia.to("cpu").shape == (2, 4)
    ia.fill_(7.0)
    assert d.numpy()[:, 0].tolist() == [7, 4, 7]
    ia.assign(np.ones((2, 4), np.float32))
    assert d.numpy()[:, 0].tolist() == [1, 4, 1]
    ia.zero_()
    assert d.numpy()[:, 0].tolist() == [0, 4, 0]
    assert "[[0." in str(ia)
    with pytest.raises(KdslError, match="does not fit"):
        ia.assign(np.ones((3, 4), np.float32))
    with pytest.raises(KdslError, match="annotation"):
        wp.indexedarray(dtype=float).numpy()
    v = wp.zeros(3, dtype=wp.vec3)
    wp.indexedarray(v, [wp.array([1], dtype=wp.int32)]).fill_(wp.vec3(1.0, 2.0, 3.0))
    assert v.numpy()[1].tolist() == [1, 2, 3] and v.numpy()[0].tolist() == [0, 0, 0]


# --- strided arrays in kernels -----------------------------------------------------
@wp.kernel
def _square(x: wp.array2d(dtype=float), y: wp.array2d(dtype=float)):
    i, j = wp.tid()
    y[i, j] = x[i, j] * x[i, j]


def _strided_launch_and_grad(backend, device):
    a = _grid((3, 4), device=device, requires_grad=True)
    t = a.transpose()[::2]  # (2, 3): t[i, j] = a[j, 2 i]
    assert not t.is_contiguous
    y = wp.zeros((2, 3), dtype=float, device=device, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(_square, dim=(2, 3), inputs=[t], outputs=[y], device=device, backend=backend)
    y.grad.fill_(1.0)
    tape.backward()
    x = a.numpy().T[::2]
    np.testing.assert_allclose(y.numpy(), x * x)
    want = np.zeros((3, 4), np.float32)
    want[:, ::2] = 2 * a.numpy()[:, ::2]
    np.testing.assert_allclose(a.grad.numpy(), want)


@pytest.mark.parametrize("backend", BACKENDS)
def test_strided_views_launch_and_differentiate(backend):
    _strided_launch_and_grad(backend, "cpu")


@pytest.mark.parametrize("backend", BACKENDS)
def test_negative_steps_and_strided_outputs(backend):
    a = _grid((2, 3))
    out = wp.zeros((3, 2))
    wp.launch(_square, dim=(2, 3), inputs=[a[:, ::-1]], outputs=[out.transpose()],
              backend=backend)  # fmt: skip
    np.testing.assert_array_equal(out.numpy(), (a.numpy()[:, ::-1] ** 2).T)


@cuda
def test_strided_views_launch_and_differentiate_cuda():
    _strided_launch_and_grad("cuda", "cuda:0")


@cuda
def test_views_on_cuda():
    a = _grid((2, 3), device="cuda:0", requires_grad=True)
    t = a.transpose()
    assert t.grad.ptr == a.grad.ptr and t.strides == (4, 12)
    np.testing.assert_array_equal(t.contiguous().numpy(), a.numpy().T)
    f = wp.zeros(2, dtype=wp.vec3, device="cuda:0").view(float)
    assert f.shape == (2, 3)
    f[1, 1] = 3.0
    assert f.numpy()[1, 1] == 3.0
    back = wp.array(ptr=a.ptr, dtype=float, shape=(6,), device="cuda:0")
    assert back.numpy().tolist() == [0, 1, 2, 3, 4, 5]
    ia = wp.indexedarray(a, [wp.array([1], dtype=wp.int32, device="cuda:0"), None])
    ia.fill_(9.0)
    assert a.numpy()[1].tolist() == [9, 9, 9]
    assert a.to("cpu", requires_grad=False).device.is_cpu
