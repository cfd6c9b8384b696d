"""Paddle: ``from_paddle``, ``to_paddle`` and the device, dtype and stream helpers.

Both directions go through DLPack capsules, which every Paddle release with
``paddle.utils.dlpack`` reads and writes. A capsule carries no stream, so on a
GPU ``to_paddle`` waits for the array's kdsl stream before handing the memory
over. Gradients: Paddle says ``stop_gradient=False`` where PyTorch says
``requires_grad=True``; the tensor's gradient is read from ``.grad`` and set
with ``.grad_``. Paddle is imported only when one of these functions runs.
"""

from __future__ import annotations

from typing import Any

from kdsl.errors import KdslError
from kdsl.interop.dlpack import buffer_from_dlpack, to_dlpack
from kdsl.interop.dtypes import InteropDeviceError
from kdsl.interop.frameworks import Framework, attach_grad
from kdsl.interop.views import describe_buffer, view_buffer
from kdsl.ir import types as T
from kdsl.runtime import cuda_memory as mem
from kdsl.runtime.array import array
from kdsl.runtime.descriptor import ArrayDescriptor
from kdsl.runtime.device import Device, get_device
from kdsl.runtime.stream import Stream, get_stream

# paddle.utils.dlpack is imported too: ``import paddle`` does not make it an attribute.
PADDLE = Framework("Paddle", "paddle", ("paddle.utils.dlpack",))
_paddle = PADDLE.load


def device_from_paddle(paddle_device: Any) -> Device:
    """The kdsl device of a Paddle place or device string (``"cpu"``, ``"gpu:0"``)."""
    if isinstance(paddle_device, str):
        kind, _, index = paddle_device.partition(":")
        if kind == "cpu":
            return get_device("cpu")
        if kind in ("gpu", "cuda"):
            return PADDLE.cuda_device(int(index) if index.isdigit() else 0, paddle_device)
        raise InteropDeviceError(f"Paddle device {paddle_device!r} has no kdsl equivalent")
    place = paddle_device
    if _is(place, "is_cpu_place") or _is(place, "is_cuda_pinned_place"):
        return get_device("cpu")
    if _is(place, "is_gpu_place"):
        return PADDLE.cuda_device(int(place.gpu_device_id()), place)
    getter = getattr(place, "get_device_id", None)  # paddle.CUDAPlace
    if getter is not None:
        return PADDLE.cuda_device(int(getter()), place)
    raise PADDLE.no_device(f"Paddle place {place!r}")


def _is(place: Any, test: str) -> bool:
    fn = getattr(place, test, None)
    return bool(fn()) if callable(fn) else False


def device_to_paddle(warp_device: Any) -> str:
    """The Paddle device string of a kdsl device (``"cpu"``, ``"gpu:0"``)."""
    return PADDLE.device_string(warp_device, "gpu")


def dtype_from_paddle(paddle_dtype: Any) -> type:
    """The kdsl scalar class of a Paddle dtype; bfloat16 and complex raise ``TypeError``."""
    return PADDLE.dtype_from(paddle_dtype)


def dtype_to_paddle(warp_dtype: Any) -> Any:
    """The Paddle dtype of a kdsl scalar type; uint16/32/64 map to the signed type of their width."""
    return PADDLE.dtype_to(warp_dtype, _paddle())


def _view(t: Any, dtype: Any) -> tuple[Any, T.Type, Device]:
    paddle = _paddle()
    if not isinstance(t, paddle.Tensor):
        raise KdslError(f"from_paddle() takes a paddle.Tensor, not {type(t).__name__}")
    PADDLE.scalar(t.dtype)  # bfloat16/complex: a clear error before touching the data
    buf, dev = buffer_from_dlpack(paddle.utils.dlpack.to_dlpack(t))
    what = describe_buffer(str(t.dtype), "tensor", t.shape)
    buf, kt = view_buffer(buf, dtype, what)
    return buf, kt, dev


def from_paddle(
    t: Any,
    dtype: Any = None,
    requires_grad: bool | None = None,
    grad: Any = None,
    return_ctype: bool = False,
) -> array | ArrayDescriptor:
    """A kdsl array sharing Paddle tensor ``t``'s memory (no copy).

    Arguments as for ``from_torch``; ``requires_grad`` defaults to
    ``not t.stop_gradient``, and a missing gradient is allocated as zeros and set
    on the tensor.
    """
    buf, kt, dev = _view(t, dtype)
    if return_ctype:
        return ArrayDescriptor(buf, kt, dev, owner=t)
    a = array._wrap(buf, kt, dev)
    if requires_grad is None:
        requires_grad = not t.stop_gradient
    if requires_grad:
        if grad is None and t.grad is None:
            t.grad_ = _paddle().zeros_like(t)
        attach_grad(a, t.grad if grad is None else grad, _view)
    return a


def _tensor_of(a: array) -> Any:
    paddle = _paddle()
    et = T.elem_type(a._t)
    twin = PADDLE.twin(et)
    src = a
    if twin != et:  # Paddle has no uint16/32/64: same bits, signed
        with mem.scope(a.device):
            src = array._wrap(a._buf.view(twin.np_dtype), twin, a.device)
    if a.device.is_cuda:
        get_stream(a.device).synchronize()  # a capsule carries no stream to wait on
    return paddle.utils.dlpack.from_dlpack(to_dlpack(src))


def to_paddle(a: array, requires_grad: bool | None = None) -> Any:
    """A Paddle tensor sharing kdsl array ``a``'s memory (no copy); see ``to_torch``."""
    PADDLE.check_export(a, "to_paddle")
    out = _tensor_of(a)
    if requires_grad is None:
        requires_grad = a.requires_grad
    out.stop_gradient = not requires_grad
    if requires_grad:
        if a.grad is None:
            a.requires_grad = True  # allocates a zero grad
        out.grad_ = _tensor_of(a.grad)
    return out


def stream_from_paddle(stream_or_device: Any = None) -> Stream:
    """A kdsl ``Stream`` wrapping a Paddle CUDA stream (or a device's current one)."""
    paddle = _paddle()
    if isinstance(stream_or_device, paddle.device.Stream):
        ps = stream_or_device
    else:
        ps = paddle.device.current_stream(stream_or_device)
    s = Stream(device_from_paddle(ps.device), cuda_stream=ps.stream_base.cuda_stream)
    s._paddle_stream = ps  # keep the Paddle stream alive as long as the wrapper
    return s
