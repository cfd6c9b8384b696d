"""Arrays on CUDA devices: constructors, methods, copies, interop and launch arguments.

Every test here needs a GPU and is skipped without one (CI has none); the lead
runs them on a lent GPU machine.
"""

import gc

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslError
from kdsl.ir import types as T
from kdsl.runtime.args import ArgError, convert

pytestmark = pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")
two_gpus = pytest.mark.skipif(wp.get_cuda_device_count() < 2, reason="needs two CUDA devices")

DEV = "cuda:0"


@pytest.fixture(scope="module")
def cupy():
    import cupy

    return cupy


def test_buffer_is_a_cupy_array_with_the_layout_rule(cupy):
    a = wp.zeros(5, dtype=wp.vec3, device=DEV)
    assert isinstance(a._buf, cupy.ndarray) and a._buf.shape == (5, 3)
    assert a._buf.dtype == np.float32 and a._buf.device.id == 0
    assert a.device == DEV and a.shape == (5,) and a.strides == (12,)
    assert a.ptr == a._buf.data.ptr and a.is_contiguous
    assert a.numpy().shape == (5, 3) and type(a.numpy()) is np.ndarray
    cpu = wp.zeros(5, dtype=wp.vec3)
    assert isinstance(cpu._buf, np.ndarray)


@pytest.mark.parametrize("device", ["cuda", "cuda:0"])
def test_every_constructor(device):
    np.testing.assert_array_equal(wp.zeros((2, 3), device=device).numpy(), 0)
    assert wp.empty(4, dtype=int, device=device).shape == (4,)
    np.testing.assert_array_equal(wp.ones(3, dtype=wp.int32, device=device).numpy(), 1)
    np.testing.assert_allclose(wp.full(4, 1.25, device=device).numpy(), 1.25)
    v = wp.full(2, wp.vec3(1.0, 2.0, 3.0), device=device)
    assert v.numpy().tolist() == [[1, 2, 3]] * 2
    src = wp.array(np.arange(6, dtype=np.float32).reshape(2, 3), device=device)
    assert src.device == DEV and src.dtype is wp.float32
    for like, want in ((wp.zeros_like, 0), (wp.ones_like, 1)):
        out = like(src)
        assert out.device == DEV and out.shape == (2, 3)
        np.testing.assert_array_equal(out.numpy(), want)
    assert wp.empty_like(src).device == DEV
    np.testing.assert_array_equal(wp.full_like(src, 4).numpy(), 4)
    np.testing.assert_array_equal(wp.clone(src).numpy(), src.numpy())
    f = wp.from_numpy(np.ones((3, 2), np.float32), dtype=wp.vec2, device=device)
    assert f.shape == (3,) and f.device == DEV
    assert wp.array(dtype=float, device=device).shape == (0,)
    lst = wp.array([1, 2, 3], dtype=wp.float16, device=device)
    assert lst.numpy().dtype == np.float16


def test_requires_grad_allocates_grad_on_the_device(cupy):
    a = wp.zeros(4, device=DEV, requires_grad=True)
    assert a.grad.device == DEV and isinstance(a.grad._buf, cupy.ndarray)
    np.testing.assert_array_equal(a.grad.numpy(), 0)


def test_methods():
    a = wp.zeros(8, device=DEV)
    a.fill_(2.5)
    np.testing.assert_array_equal(a.numpy(), 2.5)
    a[:4].fill_(1.0)  # a view writes the parent
    assert a.numpy().tolist() == [1.0] * 4 + [2.5] * 4
    a.zero_()
    assert a.list() == [0.0] * 8
    a.assign(np.arange(8, dtype=np.float64))  # converted like on the CPU
    assert a[3] == 3.0 and isinstance(a[3], np.float32)
    a[2] = 9.0
    a[5:7] = 4.0
    assert a.numpy().tolist() == [0, 1, 9, 3, 4, 4, 4, 7]
    c = a.copy()
    assert c.device == DEV and c.ptr != a.ptr
    c.fill_(0.0)
    assert a[0] == 0.0 and a[1] == 1.0
    r = a.reshape((2, 4))
    assert r.shape == (2, 4) and r.ptr == a.ptr and r[1, 3] == 7.0
    assert a.flatten().ptr == a.ptr
    s = r[:, 1]
    assert not s.is_contiguous and s.strides == (16,) and s.numpy().tolist() == [1.0, 4.0]
    assert "device='cuda:0'" in repr(a) and "9." in str(a)


def test_vector_elements_and_assign_between_devices():
    v = wp.zeros(3, dtype=wp.vec3, device=DEV)
    v[1] = wp.vec3(1.0, 2.0, 3.0)
    got = v[1]
    assert isinstance(got, wp.vec3) and list(got) == [1.0, 2.0, 3.0]
    assert [list(x) for x in v.list()] == [[0, 0, 0], [1, 2, 3], [0, 0, 0]]
    host = wp.full(3, wp.vec3(5.0, 5.0, 5.0))
    v.assign(host)
    np.testing.assert_array_equal(v.numpy(), 5.0)
    back = wp.zeros(3, dtype=wp.vec3)
    back.assign(v)
    np.testing.assert_array_equal(back.numpy(), 5.0)


def test_to_moves_between_cpu_and_gpu():
    h = wp.array(np.arange(10, dtype=np.int32))
    d = h.to(DEV)
    assert d.device == DEV and d.dtype is wp.int32
    assert d.to(DEV) is d
    back = d.to("cpu")
    assert back.device == "cpu"
    np.testing.assert_array_equal(back.numpy(), np.arange(10))
    g = wp.zeros(3, device="cpu", requires_grad=True).to(DEV)
    assert g.requires_grad and g.grad.device == DEV


def test_array_from_a_gpu_array_stays_on_its_device():
    a = wp.ones(4, device=DEV)
    assert wp.array(a).device == DEV
    assert wp.array(a, device="cpu").device == "cpu"
    assert wp.array(a, dtype=wp.float64, device="cpu").numpy().dtype == np.float64


def test_cuda_array_interface_is_zero_copy_with_cupy(cupy):
    a = wp.array(np.arange(6, dtype=np.float32), device=DEV)
    face = a.__cuda_array_interface__
    assert face["version"] == 3 and face["shape"] == (6,) and face["typestr"] == "<f4"
    assert face["data"][0] == a.ptr
    assert face["stream"] == wp.get_stream(DEV).cuda_stream
    assert not hasattr(a, "__array_interface__")
    view = cupy.asarray(a)
    assert view.data.ptr == a.ptr
    view[2] = 42.0  # a write through CuPy is seen by kdsl
    cupy.cuda.Device(0).synchronize()
    assert a[2] == 42.0
    a.fill_(1.0)  # and the other way round
    wp.synchronize()
    assert float(view.sum()) == 6.0


def test_cupy_arrays_wrap_zero_copy(cupy):
    c = cupy.arange(4, dtype=cupy.float32)
    a = wp.array(c, copy=False)
    assert a.device == DEV and a.ptr == c.data.ptr
    a.fill_(3.0)
    wp.synchronize()
    assert float(c[0]) == 3.0
    copied = wp.array(c, dtype=wp.float32)
    assert copied.ptr != c.data.ptr
    vec = wp.array(cupy.zeros((2, 3), cupy.float32), dtype=wp.vec3, copy=False)
    assert vec.shape == (2,)


def test_launch_arguments_on_cuda(cupy):
    dev = wp.get_device(DEV)
    t = T.ArrayType(T.F32, 1)
    a = wp.zeros(4, device=DEV)
    assert convert(t, a, dev) is a._buf
    c = cupy.zeros(4, cupy.float32)
    wrapped = convert(t, c, dev)
    assert isinstance(wrapped, cupy.ndarray) and wrapped.data.ptr == c.data.ptr
    vt = T.ArrayType(T.VectorType(3, T.F32), 1)
    assert convert(vt, cupy.zeros((5, 3), cupy.float32), dev).shape == (5, 3)
    with pytest.raises(ArgError, match=r"got a CUDA ndarray float64 array.*astype\(np.float32\)"):
        convert(t, cupy.zeros(4, cupy.float64), dev)
    with pytest.raises(ArgError, match=r"expected a 1-d array of f32.*got shape \(2, 2\)"):
        convert(t, cupy.zeros((2, 2), cupy.float32), dev)
    with pytest.raises(ArgError, match=r"NumPy array lives on the cpu, but the launch is on"):
        convert(t, np.zeros(4, np.float32), dev)
    with pytest.raises(ArgError, match=r"on device 'cuda:0', got one on 'cpu'"):
        convert(t, wp.zeros(4), dev)
    with pytest.raises(ArgError, match=r"on device 'cpu', got one on 'cuda:0'"):
        convert(t, a, wp.get_device("cpu"))
    with pytest.raises(ArgError, match=r"device 'cpu', got a CUDA ndarray"):
        convert(t, c, wp.get_device("cpu"))
    assert convert(T.F32, 2, dev) == np.float32(2)  # scalars convert as on the CPU


def test_copy_between_host_and_device_with_offsets():
    h = wp.array(np.arange(10, dtype=np.float32))
    d = wp.zeros(10, device=DEV)
    wp.copy(d, h, dest_offset=2, src_offset=5, count=3)
    assert d.numpy().tolist() == [0, 0, 5, 6, 7, 0, 0, 0, 0, 0]
    back = wp.zeros(10)
    wp.copy(back, d)
    wp.synchronize()  # copies to the CPU are asynchronous (the seeds' FAQ)
    np.testing.assert_array_equal(back.numpy(), d.numpy())
    with pytest.raises(KdslError, match="out of range"):
        wp.copy(d, h, dest_offset=8, count=5)


def test_copy_into_and_out_of_strided_views():
    d = wp.zeros((4, 4), dtype=wp.int32, device=DEV)
    col = d[:, 1]
    wp.copy(col, wp.array(np.array([1, 2, 3, 4], np.int32)))
    assert d.numpy()[:, 1].tolist() == [1, 2, 3, 4] and d.numpy().sum() == 10
    out = wp.zeros((2, 2), dtype=wp.int32)[:, 0]  # a strided host destination
    wp.copy(out, col, src_offset=2, count=2)
    wp.synchronize()
    assert out.numpy().tolist() == [3, 4]
    same = wp.zeros(4, dtype=wp.int32, device=DEV)
    wp.copy(same, col)
    assert same.numpy().tolist() == [1, 2, 3, 4]


def test_copy_after_fill_sees_the_fill():
    # Both are enqueued on cuda:0's current stream, so no synchronization is needed between them.
    n = 1 << 24
    a = wp.zeros(n, device=DEV)
    b = wp.empty(n, device=DEV)
    for value in (1.0, 2.0, 3.0):
        a.fill_(value)
        wp.copy(b, a)
        assert b[n - 1] == value
    host = wp.empty(n, device="cpu")
    a.fill_(4.0)
    wp.copy(host, a)
    wp.synchronize()
    assert host.numpy()[-1] == 4.0 and host.numpy()[0] == 4.0


def test_copy_on_an_explicit_stream():
    s = wp.Stream(DEV)
    a = wp.full(1 << 20, 5.0, device=DEV)
    b = wp.zeros(1 << 20, device=DEV)
    wp.copy(b, a, stream=s)  # s first waits for the device's current stream
    wp.synchronize_stream(s)
    assert b[(1 << 20) - 1] == 5.0


@two_gpus
def test_copy_between_two_gpus():
    a = wp.array(np.arange(1000, dtype=np.float32), device="cuda:0")
    b = wp.zeros(1000, device="cuda:1")
    wp.copy(b, a, dest_offset=10, src_offset=0, count=990)
    got = b.numpy()
    assert got[:10].tolist() == [0] * 10 and got[10:].tolist() == list(range(990))
    c = a.to("cuda:1")
    assert c.device == "cuda:1" and c._buf.device.id == 1
    np.testing.assert_array_equal(c.numpy(), np.arange(1000))
    d = wp.clone(c, device="cuda:0")
    np.testing.assert_array_equal(d.numpy(), np.arange(1000))
    strided = wp.zeros((1000, 2), device="cuda:1")[:, 1]
    wp.copy(strided, a)
    np.testing.assert_array_equal(strided.numpy(), np.arange(1000))
    with pytest.raises(ArgError, match="on device 'cuda:1', got one on 'cuda:0'"):
        convert(T.ArrayType(T.F32, 1), a, wp.get_device("cuda:1"))


def test_out_of_memory_is_a_clear_error():
    import cupy

    pool = cupy.get_default_memory_pool()
    gc.collect()  # arrays of earlier tests that are already dead leave the pool first
    used_before = pool.used_bytes()
    with pytest.raises(
        KdslError, match=r"out of memory on 'cuda:0': cannot allocate 10000000000000 bytes"
    ):
        wp.empty(10**13 // 4, dtype=wp.float32, device=DEV)
    with pytest.raises(KdslError, match="out of memory on 'cuda:0'"):
        wp.zeros(10**13 // 4, device=DEV, requires_grad=True)
    wp.synchronize()
    # Nothing was kept: the pool holds no more than before (the device's free memory
    # is no measure: other tests of this process leave cached blocks in the pool).
    gc.collect()
    assert pool.used_bytes() <= used_before
