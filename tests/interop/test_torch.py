"""PyTorch on the CPU: from_torch/to_torch zero-copy, grads, helpers, direct launch, errors."""

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslError, KdslLaunchError
from tests.interop.kernels import double_vec, saxpy

torch = pytest.importorskip("torch")


def test_from_torch_is_zero_copy():
    t = torch.arange(4, dtype=torch.float32)
    a = wp.from_torch(t)
    assert a.dtype is wp.float32 and a.device == "cpu" and a.ptr == t.data_ptr()
    a[1] = 10.0
    assert t[1].item() == 10.0
    t[2] = -1.0
    assert a.numpy()[2] == -1.0


def test_from_torch_vector_dtype_maps_inner_dims():
    t = torch.zeros(5, 3)
    a = wp.from_torch(t, dtype=wp.vec3)
    assert a.shape == (5,) and a.dtype is wp.vec3 and a.ptr == t.data_ptr()
    m = wp.from_torch(torch.zeros(2, 3, 3), dtype=wp.mat33)
    assert m.shape == (2,) and m.dtype is wp.mat33
    wp.launch(double_vec, dim=5, inputs=[wp.from_torch(t.fill_(1.5), dtype=wp.vec3)])
    assert (t == 3.0).all()


def test_from_torch_strided_outer_dims_are_fine():
    t = torch.arange(20, dtype=torch.float32).reshape(4, 5)
    a = wp.from_torch(t[:, 1])  # a strided column
    assert a.shape == (4,) and a.strides == (20,)
    assert a.numpy().tolist() == [1.0, 6.0, 11.0, 16.0]


def test_from_torch_errors():
    with pytest.raises(TypeError, match="bfloat16 has no kdsl equivalent"):
        wp.from_torch(torch.zeros(2, dtype=torch.bfloat16))
    with pytest.raises(KdslError, match="complex64 has no kdsl equivalent"):
        wp.from_torch(torch.zeros(2, dtype=torch.complex64))
    with pytest.raises(KdslError, match="must be contiguous"):
        wp.from_torch(torch.zeros(3, 4).t(), dtype=wp.vec3)
    with pytest.raises(KdslError, match="last dim must be 3"):
        wp.from_torch(torch.zeros(4, 2), dtype=wp.vec3)
    with pytest.raises(KdslError, match="components are float32"):
        wp.from_torch(torch.zeros(4, 3, dtype=torch.float64), dtype=wp.vec3)
    with pytest.raises(KdslError, match=r"takes a torch\.Tensor"):
        wp.from_torch(np.zeros(3))


def test_from_torch_requires_grad_allocates_and_shares_grad():
    t = torch.ones(3, requires_grad=True)
    a = wp.from_torch(t)
    assert a.requires_grad and t.grad is not None
    assert a.grad.ptr == t.grad.data_ptr()
    a.grad.fill_(4.0)
    assert t.grad.tolist() == [4.0, 4.0, 4.0]
    b = wp.from_torch(torch.ones(3, requires_grad=True), requires_grad=False)
    assert not b.requires_grad and b.grad is None


def test_from_torch_explicit_grad_and_vector_grad():
    t = torch.zeros(4, 3)
    g = torch.zeros(4, 3)
    a = wp.from_torch(t, dtype=wp.vec3, requires_grad=True, grad=g)
    assert a.grad.ptr == g.data_ptr() and a.grad.dtype is wp.vec3
    assert t.grad is None  # an explicit grad is not attached to the tensor


def test_to_torch_is_zero_copy_and_appends_element_dims():
    a = wp.zeros(3, dtype=wp.vec3)
    t = wp.to_torch(a)
    assert t.shape == (3, 3) and t.dtype == torch.float32 and t.data_ptr() == a.ptr
    t[0, 2] = 7.0
    assert a.numpy()[0, 2] == 7.0
    u = wp.to_torch(wp.full(2, 5, dtype=wp.uint32))
    assert u.dtype == torch.int32 and u.tolist() == [5, 5]


def test_to_torch_shares_grad():
    a = wp.zeros(4, dtype=float, requires_grad=True)
    t = wp.to_torch(a)
    assert t.requires_grad and t.is_leaf
    assert t.grad.data_ptr() == a.grad.ptr
    b = wp.zeros(2, dtype=float)
    tb = wp.to_torch(b, requires_grad=True)
    assert b.grad is not None and tb.grad.data_ptr() == b.grad.ptr
    assert not wp.to_torch(
        wp.zeros(2, dtype=float, requires_grad=True), requires_grad=False
    ).requires_grad
    with pytest.raises(KdslError, match="needs a float array"):
        wp.to_torch(wp.zeros(2, dtype=int), requires_grad=True)


def test_torch_optimizer_updates_kdsl_array():
    xs = wp.array(np.ones((4, 2), np.float32), dtype=wp.float32, requires_grad=True)
    opt = torch.optim.SGD([wp.to_torch(xs)], lr=0.5)
    xs.grad.fill_(1.0)  # a gradient computed by kdsl
    opt.step()
    assert np.allclose(xs.numpy(), 0.5)


def test_round_trip():
    t = torch.arange(6, dtype=torch.float64)
    back = wp.to_torch(wp.from_torch(t))
    assert back.data_ptr() == t.data_ptr() and back.dtype == torch.float64


def test_return_ctype_descriptor_launches():
    x = torch.arange(4, dtype=torch.float32)
    y = torch.ones(4)
    xd = wp.from_torch(x, return_ctype=True)
    yd = wp.from_torch(y, return_ctype=True)
    assert isinstance(xd, wp.ArrayDescriptor) and xd.shape == (4,) and xd.device == "cpu"
    wp.launch(saxpy, dim=4, inputs=[xd, yd, 2.0])
    assert y.tolist() == [1.0, 3.0, 5.0, 7.0]


def test_tensors_launch_directly():
    x = torch.arange(4, dtype=torch.float32)
    y = torch.ones(4, requires_grad=True)  # read through detach(): same memory
    wp.launch(saxpy, dim=4, inputs=[x, y, 1.0])
    assert y.detach().tolist() == [1.0, 2.0, 3.0, 4.0]
    v = torch.ones(2, 3)
    wp.launch(double_vec, dim=2, inputs=[v])
    assert (v == 2.0).all()


def test_direct_launch_errors():
    y = torch.ones(4)
    with pytest.raises(KdslLaunchError, match=r"got a torch float64 array; convert it with \.to"):
        wp.launch(saxpy, dim=4, inputs=[torch.zeros(4, dtype=torch.float64), y, 1.0])
    with pytest.raises(KdslLaunchError, match=r"bfloat16 tensor.*no kdsl equivalent"):
        wp.launch(saxpy, dim=4, inputs=[torch.zeros(4, dtype=torch.bfloat16), y, 1.0])
    with pytest.raises(KdslLaunchError, match="expected a 1-d array"):
        wp.launch(saxpy, dim=4, inputs=[torch.zeros(4, 2), y, 1.0])
    with pytest.raises(KdslLaunchError, match="argument 2 'a': expected f32"):
        wp.launch(saxpy, dim=4, inputs=[y, y, torch.tensor(1.0)])


def test_device_helpers():
    assert wp.device_from_torch("cpu") == "cpu"
    assert wp.device_from_torch(torch.device("cpu")) == "cpu"
    assert wp.device_to_torch("cpu") == "cpu"
    assert wp.device_to_torch(wp.get_device("cpu")) == "cpu"
    with pytest.raises(RuntimeError, match="no kdsl equivalent"):
        wp.device_from_torch("meta")
    if not wp.is_cuda_available():
        with pytest.raises(KdslError, match="not available"):
            wp.device_from_torch("cuda:0")


@pytest.mark.parametrize(
    "wp_type, torch_type",
    [(wp.float16, "float16"), (wp.float32, "float32"), (wp.float64, "float64"),
     (wp.int8, "int8"), (wp.int16, "int16"), (wp.int32, "int32"), (wp.int64, "int64"),
     (wp.uint8, "uint8"), (wp.bool, "bool")],
)  # fmt: skip
def test_dtype_helpers_round_trip(wp_type, torch_type):
    tt = getattr(torch, torch_type)
    assert wp.dtype_to_torch(wp_type) == tt
    assert wp.dtype_from_torch(tt) is wp_type


def test_dtype_helper_edges():
    assert wp.dtype_to_torch(wp.uint32) == torch.int32  # the seed's signed mapping
    assert wp.dtype_to_torch(wp.uint64) == torch.int64
    assert wp.dtype_to_torch(float) == torch.float32
    for bad in (torch.bfloat16, torch.complex64, torch.complex128):
        with pytest.raises(TypeError, match="no kdsl equivalent"):
            wp.dtype_from_torch(bad)
    with pytest.raises(TypeError, match="vec3f has no torch dtype"):
        wp.dtype_to_torch(wp.vec3)


def test_stream_helpers_without_cuda():
    if wp.is_cuda_available():
        pytest.skip("checks the no-GPU errors")
    with pytest.raises(KdslError):
        wp.stream_to_torch("cpu")
    with pytest.raises(KdslError):
        wp.stream_from_torch()
