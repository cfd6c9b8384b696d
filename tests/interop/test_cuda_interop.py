"""Interop on a GPU: DLPack with streams, CuPy, Numba, PyTorch and JAX CUDA arrays.

Every test needs a GPU (skipped without one; CI has none) and the framework it
uses (skipped when it is missing). The lead runs them on a lent GPU machine.
"""

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslError, KdslLaunchError
from tests.interop.kernels import double_vec, saxpy

pytestmark = pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")
DEV = "cuda:0"


@pytest.fixture(scope="module")
def cp():
    return pytest.importorskip("cupy")


@pytest.fixture(scope="module")
def torch():
    torch = pytest.importorskip("torch")
    if not torch.cuda.is_available():
        pytest.skip("this PyTorch has no CUDA")
    return torch


@pytest.fixture(scope="module")
def jax():
    jax = pytest.importorskip("jax")
    try:
        jax.devices("cuda")
    except RuntimeError:
        pytest.skip("this JAX has no CUDA backend")
    return jax


# --- DLPack and CuPy -----------------------------------------------------------
def test_dlpack_device_and_cupy_import_zero_copy(cp):
    a = wp.zeros(4, dtype=wp.vec3, device=DEV)
    assert a.__dlpack_device__() == (2, 0)
    c = cp.from_dlpack(a)  # CuPy passes its stream; kdsl's stream is waited on
    assert c.shape == (4, 3) and c.data.ptr == a.ptr
    c[1] = 5.0
    assert a.numpy()[1].tolist() == [5.0, 5.0, 5.0]


def test_dunder_dlpack_capsule_kinds_on_cuda(cp):
    a = wp.zeros(3, device=DEV)
    s = wp.get_stream(DEV).cuda_stream
    assert "dltensor_versioned" in repr(a.__dlpack__(stream=s, max_version=(1, 0)))
    assert '"dltensor"' in repr(a.__dlpack__(stream=s))


@pytest.mark.parametrize("versioned", [False, True])
def test_from_dlpack_cupy_capsules_and_objects(cp, versioned):
    src = cp.arange(6, dtype=cp.float32)
    cap = src.__dlpack__(max_version=(1, 0)) if versioned else src.__dlpack__()
    a = wp.from_dlpack(cap)
    assert a.device == DEV and a.ptr == src.data.ptr
    b = wp.from_dlpack(src.reshape(2, 3), dtype=wp.vec3)
    assert b.shape == (2,) and b.ptr == src.data.ptr
    a.fill_(3.0)
    assert float(src.sum().get()) == 18.0


def test_to_dlpack_on_cuda(cp):
    a = wp.full(4, 2.0, dtype=float, device=DEV)
    wp.synchronize()  # to_dlpack does no stream synchronization, as the seed says
    c = cp.from_dlpack(wp.to_dlpack(a))
    assert c.data.ptr == a.ptr and float(c.sum().get()) == 8.0


def test_cupy_arrays_launch_directly(cp):
    x = cp.arange(4, dtype=cp.float32)
    y = cp.ones(4, dtype=cp.float32)
    wp.launch(saxpy, dim=4, inputs=[x, y, 2.0], device=DEV)
    assert y.get().tolist() == [1.0, 3.0, 5.0, 7.0]
    with pytest.raises(KdslLaunchError, match="expected an array on device 'cpu', got a CUDA"):
        wp.launch(saxpy, dim=4, inputs=[x, y, 2.0], device="cpu")


def test_numba_arrays_through_the_cuda_array_interface():
    numba_cuda = pytest.importorskip("numba.cuda")
    if not numba_cuda.is_available():
        pytest.skip("Numba sees no GPU")
    d = numba_cuda.to_device(np.arange(4, dtype=np.float32))
    y = wp.zeros(4, dtype=float, device=DEV)
    wp.launch(saxpy, dim=4, inputs=[d, y, 1.0], device=DEV)
    assert y.numpy().tolist() == [0.0, 1.0, 2.0, 3.0]
    a = wp.array(d, dtype=wp.float32, copy=False)
    assert a.ptr == d.__cuda_array_interface__["data"][0]
    n = numba_cuda.as_cuda_array(y)  # Numba reads kdsl's interface (with its stream)
    assert n.copy_to_host().tolist() == [0.0, 1.0, 2.0, 3.0]


# --- PyTorch ---------------------------------------------------------------------
def test_from_torch_cuda_is_zero_copy(torch):
    t = torch.zeros(5, 3, device=DEV)
    a = wp.from_torch(t, dtype=wp.vec3)
    assert a.device == DEV and a.ptr == t.data_ptr() and a.shape == (5,)
    t.fill_(1.0)
    torch.cuda.synchronize()
    wp.launch(double_vec, dim=5, inputs=[a], device=DEV)
    wp.synchronize()
    assert (t == 2.0).all().item()


def test_to_torch_cuda_is_zero_copy_and_ordered(torch):
    a = wp.zeros(1 << 16, dtype=float, device=DEV)
    a.fill_(4.0)  # enqueued on kdsl's stream; to_torch makes torch's stream wait
    t = wp.to_torch(a)
    assert t.device.type == "cuda" and t.data_ptr() == a.ptr
    assert t.sum().item() == 4.0 * (1 << 16)


def test_torch_grads_on_cuda(torch):
    t = torch.ones(3, device=DEV, requires_grad=True)
    a = wp.from_torch(t)
    assert a.grad.ptr == t.grad.data_ptr() and a.grad.device == DEV
    b = wp.zeros(3, dtype=float, device=DEV, requires_grad=True)
    tb = wp.to_torch(b)
    assert tb.grad.data_ptr() == b.grad.ptr


def test_torch_cuda_tensors_launch_directly_and_as_descriptors(torch):
    x = torch.arange(4, dtype=torch.float32, device=DEV)
    y = torch.ones(4, device=DEV, requires_grad=True)
    wp.launch(saxpy, dim=4, inputs=[x, y, 1.0], device=DEV)
    wp.launch(
        saxpy, dim=4, device=DEV,
        inputs=[wp.from_torch(x, return_ctype=True), wp.from_torch(y, return_ctype=True), 1.0],
    )  # fmt: skip
    wp.synchronize()
    assert y.detach().cpu().tolist() == [1.0, 3.0, 5.0, 7.0]


def test_torch_wrong_device_errors(torch):
    with pytest.raises(KdslLaunchError, match="expected an array on device 'cpu'"):
        wp.launch(saxpy, dim=4, inputs=[torch.zeros(4, device=DEV), np.zeros(4, np.float32), 1.0])
    with pytest.raises(KdslLaunchError, match=r"torch\.float32 tensor in host memory .* 'cuda:0'"):
        wp.launch(
            saxpy, dim=4, device=DEV,
            inputs=[torch.zeros(4), torch.zeros(4, device=DEV), 1.0],
        )  # fmt: skip
    d = wp.from_torch(torch.zeros(4), return_ctype=True)
    with pytest.raises(KdslLaunchError, match="expected an array on device 'cuda:0', got one on"):
        wp.launch(saxpy, dim=4, inputs=[d, d, 1.0], device=DEV)


def test_torch_device_and_stream_helpers(torch):
    assert wp.device_from_torch("cuda:0") == DEV
    assert wp.device_from_torch(torch.device("cuda")) == f"cuda:{torch.cuda.current_device()}"
    assert wp.device_to_torch(DEV) == "cuda:0"
    ts = torch.cuda.Stream(device=DEV)
    ws = wp.stream_from_torch(ts)
    assert ws.cuda_stream == ts.cuda_stream and ws.device == DEV
    assert wp.stream_from_torch(DEV).cuda_stream == torch.cuda.current_stream(0).cuda_stream
    back = wp.stream_to_torch(wp.get_stream(DEV))
    assert back.cuda_stream == wp.get_stream(DEV).cuda_stream
    assert wp.stream_to_torch(DEV).cuda_stream == wp.get_stream(DEV).cuda_stream
    with pytest.raises(KdslError):
        wp.stream_from_torch("cpu")


# --- JAX -------------------------------------------------------------------------
def test_jax_cuda_round_trip_zero_copy(jax):
    jnp = jax.numpy
    gpu = wp.device_to_jax(DEV)
    assert wp.device_from_jax(gpu) == DEV
    j = jax.device_put(jnp.arange(6, dtype=jnp.float32).reshape(2, 3), gpu)
    a = wp.from_jax(j, dtype=wp.vec3)
    assert a.device == DEV and a.ptr == j.unsafe_buffer_pointer()
    b = wp.full(8, 1.5, dtype=float, device=DEV)
    jb = wp.to_jax(b)
    assert jb.unsafe_buffer_pointer() == b.ptr and float(jb.sum()) == 12.0
