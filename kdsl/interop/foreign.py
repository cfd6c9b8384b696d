"""Launch arguments from other frameworks: DLPack and ``__array_interface__`` producers.

The runtime's argument conversion (``kdsl.runtime.args``) handles kdsl arrays, NumPy
and ``__cuda_array_interface__`` objects itself; anything else that speaks DLPack or
the array interface (PyTorch tensors, JAX arrays, ...) reaches ``foreign_buffer``
through the runtime's adapter registry (``kdsl.runtime.adapters``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from kdsl.errors import KdslError
from kdsl.interop import dlpack
from kdsl.interop.dtypes import InteropTypeError
from kdsl.interop.torch import TORCH, VIEWS, is_tensor, scalar_of
from kdsl.interop.torch_streams import kdsl_waits_for_torch, raw_stream_reader
from kdsl.ir import types as T
from kdsl.runtime.args import ArgError, check_foreign, has_attribute
from kdsl.runtime.device import Device

torch_view = VIEWS.view


def foreign_buffer(t: T.ArrayType, value: Any, device: Device) -> Any:
    """A DLPack or ``__array_interface__`` producer (not NumPy, not CUDA-interface) as a buffer.

    PyTorch tensors that require grad are read through ``detach()`` (same memory);
    host data becomes a NumPy view, CUDA data a CuPy view, both zero-copy.
    """
    # what: for dtype messages ("a torch float64 array"); label: for device messages
    what = label = type(value).__name__
    fix = ".astype(np.{})"
    if is_tensor(value):
        what, label, fix = "torch", f"{value.dtype} tensor", ".to(torch.{})"
        try:
            scalar_of(value.dtype)
        except InteropTypeError as e:
            raise ArgError(
                f"expected an array of {t.dtype}, got a {value.dtype} tensor: {e}"
            ) from None
        value = value.detach()
    if has_attribute(value, "__dlpack__"):
        try:
            kind, _ = dlpack.dlpack_device(value)
        except Exception as e:  # a producer that cannot say where its data is
            raise ArgError(f"expected an array of {t.dtype}, got a {label} ({e})") from None
        if kind in dlpack.CUDA_TYPES and device.is_cpu:
            raise ArgError(f"expected an array on device 'cpu', got a CUDA {label} (device memory)")
        if kind in dlpack.HOST_TYPES and not device.is_cpu:
            raise ArgError(
                f"a {label} in host memory cannot be used by a launch on '{device}'; "
                f"move it to '{device}' first"
            )
        try:
            buf, where = dlpack.buffer_from_dlpack(value)
        except KdslError as e:
            raise ArgError(f"expected an array of {t.dtype}, got a {label}: {e.message}") from None
        if where != device:
            raise ArgError(f"expected an array on device '{device}', got a {label} on '{where}'")
    else:
        if not device.is_cpu:
            raise ArgError(
                f"a {label} (__array_interface__, host memory) cannot be used by a launch on "
                f"'{device}'; move it to '{device}' first"
            )
        buf = np.asarray(value)
    check_foreign(t, buf.dtype, buf.shape, what, fix)
    return buf


def cached_buffer(t: T.ArrayType, value: Any, device: Device) -> Any:
    """A PyTorch tensor on the launch's device, through ``from_torch``'s view cache; else None.

    The launch path asks this first, before the general (slower) checks: a tensor
    handed to launches again and again costs a few comparisons and gives the same
    buffer object every time, which lets the launch reuse its packed arguments. A
    CUDA tensor's view is its address (as Warp reads it), and kdsl's stream is made
    to wait for PyTorch's current one where CUDA does not already order them
    (``torch_streams``). None (another object, a tensor on another device, one the
    cache cannot view) sends the value down the general path, which words every error.
    """
    if not is_tensor(value) or value.is_cuda == device.is_cpu:
        return None
    try:
        buf, _, dev = torch_view(value)
    except (KdslError, TypeError, RuntimeError):  # numpy() refuses some tensors (neg bit)
        return None
    if dev != device:
        return None
    check_foreign(t, buf.dtype, buf.shape, "torch", ".to(torch.{})")
    if device.is_cuda:
        kdsl_waits_for_torch(device, raw_stream_reader(TORCH.load())(device.ordinal))
    return buf
