"""PyTorch: ``from_torch``, ``to_torch`` and the device, dtype and stream helpers.

Conversions share memory both ways. A CPU tensor is read through ``Tensor.numpy``
and a CUDA tensor through its data pointer (a CuPy view that keeps the tensor
alive). ``to_torch`` of a GPU array builds the tensor from the buffer's address
(``__cuda_array_interface__``, as Warp does) when CUDA already orders PyTorch's
current stream after kdsl's (``torch_streams``), and goes through DLPack, which
makes PyTorch's stream wait with an event, when it does not. Gradients are shared too: ``from_torch(t, requires_grad=True)``
wraps ``t.grad`` (allocated as zeros when missing) as the array's ``grad``, and
``to_torch(a, requires_grad=True)`` makes ``a.grad`` the tensor's ``.grad``.
PyTorch is imported only when one of these functions runs.
"""

from __future__ import annotations

import functools
import weakref
from typing import Any

import numpy as np

from kdsl.errors import KdslError
from kdsl.interop.dlpack import Exporter
from kdsl.interop.dtypes import InteropDeviceError, framework_name
from kdsl.interop.frameworks import Framework, attach_grad
from kdsl.interop.tensor_cache import TensorViews
from kdsl.interop.torch_streams import needs_wait, raw_stream_reader
from kdsl.interop.views import describe_buffer, view_buffer
from kdsl.ir import types as T
from kdsl.runtime import cuda_memory as mem
from kdsl.runtime.array import array
from kdsl.runtime.descriptor import ArrayDescriptor
from kdsl.runtime.device import Device, get_device
from kdsl.runtime.stream import Stream, get_stream

TORCH = Framework("torch", "torch")
_torch = TORCH.load


def is_tensor(value: Any) -> bool:
    """True for a ``torch.Tensor``, without importing torch when nothing else has."""
    torch = TORCH.loaded()
    return torch is not None and isinstance(value, torch.Tensor)


def device_from_torch(torch_device: Any) -> Device:
    """The kdsl device of a torch device or device string (``"cuda"`` = torch's current GPU)."""
    torch = _torch()
    try:
        d = torch.device(torch_device)
    except (RuntimeError, TypeError) as e:
        raise InteropDeviceError(f"{torch_device!r} is not a torch device: {e}") from None
    if d.type == "cpu":
        return get_device("cpu")
    if d.type == "cuda":
        return TORCH.cuda_device(d.index if d.index is not None else torch.cuda.current_device(), d)
    raise TORCH.no_device(f"torch device '{d}'")


def device_to_torch(warp_device: Any) -> str:
    """The torch device string of a kdsl device (``"cpu"``, ``"cuda:0"``)."""
    return TORCH.device_string(warp_device, "cuda")


def dtype_from_torch(torch_dtype: Any) -> type:
    """The kdsl scalar class of a torch dtype; bfloat16 and complex raise ``TypeError``."""
    return TORCH.dtype_from(torch_dtype)


scalar_of = TORCH.scalar


def dtype_to_torch(warp_dtype: Any) -> Any:
    """The torch dtype of a kdsl scalar type; uint16/32/64 map to the signed type of their width."""
    return TORCH.dtype_to(warp_dtype, _torch())


def _tensor_buffer(t: Any, dev: Device) -> Any:
    """A zero-copy NumPy (CPU) or CuPy (CUDA) view of tensor ``t``."""
    t = t.detach()  # no autograd on the view; the storage is the same
    if dev.is_cpu:
        return t.numpy()
    np_dtype = np.dtype(framework_name(t.dtype))
    shape = tuple(t.shape)
    cp = mem.cupy()
    if t.numel() == 0:
        with mem.scope(dev):
            return cp.empty(shape, np_dtype)
    size = t.element_size()
    # The bytes the view may touch: from the first element to the farthest one.
    span = (1 + sum((n - 1) * s for n, s in zip(shape, t.stride()))) * size
    memory = cp.cuda.UnownedMemory(t.data_ptr(), span, t, dev.ordinal)
    strides = tuple(s * size for s in t.stride())
    with mem.scope(dev):
        return cp.ndarray(shape, np_dtype, cp.cuda.MemoryPointer(memory, 0), strides=strides)


def _build_view(t: Any, dtype: Any) -> tuple[Any, T.Type, Device]:
    """Tensor ``t`` seen as a kdsl buffer of ``dtype``: checked, uncached."""
    torch = _torch()
    if not isinstance(t, torch.Tensor):
        raise KdslError(f"from_torch() takes a torch.Tensor, not {type(t).__name__}")
    dev = device_from_torch(t.device)
    scalar_of(t.dtype)  # bfloat16/complex: a clear error before touching the data
    what = describe_buffer(str(t.dtype), "tensor", t.shape)
    buf, kt = view_buffer(_tensor_buffer(t, dev), dtype, what)
    return buf, kt, dev


#: Views of the tensors seen last, so a tensor handed over again costs a few checks.
VIEWS = TensorViews(_build_view)
_view = VIEWS.view


def from_torch(
    t: Any,
    dtype: Any = None,
    requires_grad: bool | None = None,
    grad: Any = None,
    return_ctype: bool = False,
) -> array | ArrayDescriptor:
    """A kdsl array sharing tensor ``t``'s memory (no copy).

    ``dtype`` defaults to the tensor's; a vector or matrix dtype takes the trailing
    dims as components (an ``(n, 3)`` float32 tensor with ``dtype=vec3`` gives a
    length-n ``vec3`` array). ``requires_grad`` (default: ``t.requires_grad``) makes
    the array's ``grad`` share ``grad`` if given, else ``t.grad``, which is allocated
    as zeros when missing. ``return_ctype=True`` returns an ``ArrayDescriptor``
    instead: cheaper to build, accepted by ``launch``, no ``grad``.
    """
    buf, kt, dev = _view(t, dtype)
    if return_ctype:
        return ArrayDescriptor(buf, kt, dev, owner=t)
    a = array._wrap(buf, kt, dev)
    if requires_grad is None:
        requires_grad = bool(t.requires_grad)
    if requires_grad:
        if grad is None and t.grad is None:
            t.grad = _torch().zeros_like(t, requires_grad=False)
        view = lambda g, kt: _grad_view(t, dev, g, kt)  # noqa: E731
        attach_grad(a, t.grad if grad is None else grad, view)
    return a


def _grad_view(t: Any, dev: Device, g: Any, dtype: Any) -> tuple[Any, T.Type, Device]:
    """``_view`` of a gradient tensor ``g``, which must match tensor ``t`` in shape and device."""
    if tuple(g.shape) != tuple(t.shape):
        raise KdslError(
            f"from_torch(): grad has shape {tuple(g.shape)}, the tensor {tuple(t.shape)}"
        )
    gbuf, gt, gdev = _view(g, dtype)
    if gdev != dev:
        raise KdslError(f"from_torch(): grad is on '{gdev}', the tensor on '{dev}'")
    return gbuf, gt, gdev


class _CudaFace:
    """A CUDA buffer seen through ``__cuda_array_interface__`` version 2 (no stream: the
    caller has ordered the streams), keeping the buffer alive as long as the tensor."""

    __slots__ = ("__cuda_array_interface__", "owner")

    def __init__(self, face: dict, owner: Any) -> None:
        self.__cuda_array_interface__ = face
        self.owner = owner


@functools.cache
def _torch_device(ordinal: int) -> Any:
    return _torch().device("cuda", ordinal)


# A CUDA array's tensor, built once from its address and handed out as ``detach()``
# aliases: a new tensor object per call (its own ``requires_grad`` and ``.grad``) at a
# fifth of the cost of reading ``__cuda_array_interface__`` again. The aliases share
# one version counter, so autograd sees an in-place write through any of them.
_BASES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _cuda_tensor(buf: Any, np_dtype: np.dtype, dev: Device, owner: array | None = None) -> Any:
    """A tensor over CUDA buffer ``buf`` built from its address (Warp's way), or None.

    None where the streams need an event (DLPack orders them) or the layout is one
    ``torch.as_tensor`` reads differently (no elements, negative strides). With
    ``owner`` (the array ``buf`` belongs to) the tensor is built once per array.
    """
    torch = _torch()
    if needs_wait(dev, raw_stream_reader(torch)(dev.ordinal)) is not None:
        return None
    if owner is not None:
        cached = _BASES.get(owner)
        if cached is not None and cached[0] is buf:
            return cached[1].detach()
    base = _address_tensor(torch, buf, np_dtype, dev)
    if base is not None and owner is not None:
        _BASES[owner] = (buf, base)
        return base.detach()
    return base


def _address_tensor(torch: Any, buf: Any, np_dtype: np.dtype, dev: Device) -> Any:
    strides = buf.strides
    if buf.size == 0 or min(strides, default=0) < 0:
        return None
    face = {
        "data": (buf.data.ptr, False),
        "shape": buf.shape,
        "strides": strides,
        "typestr": np_dtype.str,
        "version": 2,
    }
    return torch.as_tensor(_CudaFace(face, buf), device=_torch_device(dev.ordinal))


def _tensor_of(buf: Any, t: T.Type, dev: Device, owner: array | None = None) -> Any:
    et = T.elem_type(t)
    twin = TORCH.twin(et)
    if dev.is_cuda:
        out = _cuda_tensor(buf, twin.np_dtype, dev, owner)
        if out is not None:
            return out
    if twin != et:  # torch has no full uint16/32/64 support: same bits, signed
        with mem.scope(dev):
            buf = buf.view(twin.np_dtype)
    torch = _torch()
    if dev.is_cpu and buf.flags.writeable:
        # No stream to order on the CPU: torch.from_numpy shares the memory as DLPack
        # would, at a tenth of the cost (the tensor keeps ``buf`` alive).
        try:
            return torch.from_numpy(buf)
        except (TypeError, ValueError):  # negative strides, a dtype torch lacks: DLPack says why
            pass
    return torch.from_dlpack(Exporter(buf, dev))


def to_torch(a: array, requires_grad: bool | None = None) -> Any:
    """A torch tensor sharing kdsl array ``a``'s memory (no copy).

    Element dims are appended (a ``vec3`` array gives an ``(n, 3)`` tensor);
    uint16/32/64 data is seen as the signed type of its width. With
    ``requires_grad`` (default: ``a.requires_grad``) the tensor requires grad and its
    ``.grad`` shares ``a.grad`` (allocated when missing).
    """
    TORCH.check_export(a, "to_torch")
    out = _tensor_of(a._buf, a._t, a.device, a)
    if requires_grad is None:
        requires_grad = a.requires_grad
    if requires_grad:
        if not T.elem_type(a._t).is_float:
            raise KdslError(f"to_torch(requires_grad=True) needs a float array, not one of {a._t}")
        if a.grad is None:
            a.requires_grad = True  # allocates a zero grad
        out.requires_grad_(True)
        out.grad = _tensor_of(a.grad._buf, a.grad._t, a.grad.device, a.grad)
    return out


def stream_from_torch(stream_or_device: Any = None) -> Stream:
    """A kdsl ``Stream`` wrapping a torch CUDA stream (or a device's current torch stream)."""
    torch = _torch()
    if isinstance(stream_or_device, torch.cuda.Stream):
        ts = stream_or_device
    else:
        if not torch.cuda.is_available():
            raise InteropDeviceError("stream_from_torch(): PyTorch sees no CUDA device")
        dev = None if stream_or_device is None else device_from_torch(stream_or_device)
        if dev is not None and not dev.is_cuda:
            raise InteropDeviceError(
                f"stream_from_torch(): '{dev}' has no streams (CPU work is synchronous)"
            )
        ts = torch.cuda.current_stream(None if dev is None else dev.ordinal)
    return Stream(device_from_torch(ts.device), cuda_stream=ts.cuda_stream)


def stream_to_torch(stream_or_device: Any = None) -> Any:
    """A ``torch.cuda.ExternalStream`` for a kdsl stream (or a device's current kdsl stream)."""
    s = stream_or_device if isinstance(stream_or_device, Stream) else get_stream(stream_or_device)
    return _torch().cuda.ExternalStream(s.cuda_stream, device=device_to_torch(s.device))
