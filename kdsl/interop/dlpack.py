"""DLPack: ``from_dlpack``, ``to_dlpack`` and the helpers the launch path and adapters share.

Producing: a kdsl array's ``__dlpack__`` hands the request to its buffer (NumPy on
the CPU, CuPy on a GPU), which writes the capsule: versioned (DLPack 1.0) when the
consumer passes ``max_version >= (1, 0)``, legacy otherwise. On a GPU the call runs
with the array's device current and its kdsl stream as CuPy's current stream, so
CuPy makes the consumer's stream wait for the work kdsl enqueued.

Consuming: any object with ``__dlpack__``/``__dlpack_device__`` or a raw capsule
(``"dltensor"`` or ``"dltensor_versioned"``). CPU data goes through
``numpy.from_dlpack``; CUDA data through ``cupy.from_dlpack``, called inside the
device's kdsl stream scope so the producer synchronizes with that stream (capsules
carry no stream: their producer already chose the order, as DLPack specifies).
"""

from __future__ import annotations

import ctypes
from typing import Any

import numpy as np

from kdsl.errors import KdslError
from kdsl.interop.dtypes import InteropDeviceError, InteropTypeError
from kdsl.interop.views import wrap
from kdsl.runtime import cuda_memory as mem
from kdsl.runtime.array import array
from kdsl.runtime.device import Device, get_device

# DLDeviceType codes (dlpack.h)
KDL_CPU, KDL_CUDA, KDL_CUDA_HOST, KDL_CUDA_MANAGED = 1, 2, 3, 13
HOST_TYPES = (KDL_CPU, KDL_CUDA_HOST)
CUDA_TYPES = (KDL_CUDA, KDL_CUDA_MANAGED)

_LEGACY, _VERSIONED = b"dltensor", b"dltensor_versioned"
# Byte offset of DLTensor.device inside the managed struct each capsule points at:
# legacy DLManagedTensor starts with the DLTensor (data pointer, then device);
# DLManagedTensorVersioned has version, manager_ctx, deleter and flags before it.
_DEVICE_OFFSET = {_LEGACY: 8, _VERSIONED: 32 + 8}

# A private handle on the C API, so setting argtypes does not touch ctypes.pythonapi's.
_capi = ctypes.PyDLL(ctypes.pythonapi._name)
_capi.PyCapsule_IsValid.argtypes = [ctypes.py_object, ctypes.c_char_p]
_capi.PyCapsule_IsValid.restype = ctypes.c_int
_capi.PyCapsule_GetPointer.argtypes = [ctypes.py_object, ctypes.c_char_p]
_capi.PyCapsule_GetPointer.restype = ctypes.c_void_p


def is_capsule(obj: Any) -> bool:
    """True for a ``PyCapsule`` (what ``to_dlpack`` functions return)."""
    return type(obj).__name__ == "PyCapsule"


def capsule_device(capsule: Any) -> tuple[int, int]:
    """The ``(device_type, device_id)`` a DLPack capsule's tensor lives on."""
    for name, offset in _DEVICE_OFFSET.items():
        if _capi.PyCapsule_IsValid(capsule, name):
            base = _capi.PyCapsule_GetPointer(capsule, name)
            pair = (ctypes.c_int32 * 2).from_address(base + offset)
            return int(pair[0]), int(pair[1])
    for name in _DEVICE_OFFSET:
        if _capi.PyCapsule_IsValid(capsule, b"used_" + name):
            raise KdslError("this DLPack capsule was already consumed (a capsule is used once)")
    raise KdslError("from_dlpack(): the capsule holds no DLPack tensor")


class _Capsule:
    """A capsule dressed as a DLPack producer, for ``numpy.from_dlpack``/``cupy.from_dlpack``."""

    def __init__(self, capsule: Any, device: tuple[int, int]) -> None:
        self._capsule = capsule
        self._device = device

    def __dlpack_device__(self) -> tuple[int, int]:
        return self._device

    def __dlpack__(self, **kwargs: Any) -> Any:
        return self._capsule  # the producer fixed version and stream order already


def cuda_device(device_id: int) -> Device:
    """The kdsl device of a DLPack CUDA device id (a clear error without that GPU)."""
    try:
        return get_device(f"cuda:{device_id}")
    except KdslError as e:
        raise InteropDeviceError(
            f"the data lives on CUDA device {device_id}: {e.message}"
        ) from None


def dlpack_device(source: Any) -> tuple[int, int]:
    """``source.__dlpack_device__()`` (or a capsule's device) as plain ints."""
    if is_capsule(source):
        return capsule_device(source)
    try:
        kind, index = source.__dlpack_device__()
        kind = int(kind)
        index = None if index is None else int(index)
    except (TypeError, ValueError) as e:
        raise InteropTypeError(
            f"{_name(source)} reports a DLPack device kdsl cannot read: {e}"
        ) from None
    if index is not None:
        return kind, index
    if kind in HOST_TYPES:
        return kind, 0  # host memory has no device index; Paddle 3.3 reports None
    raise InteropDeviceError(
        f"{_name(source)} reports DLPack device type {kind} without a device id (None), "
        "so kdsl cannot tell which GPU holds it; convert it with the framework's adapter "
        "(from_paddle, from_torch) or pass a DLPack capsule"
    )


def buffer_from_dlpack(source: Any) -> tuple[Any, Device]:
    """A NumPy or CuPy view of a DLPack producer or capsule, and its kdsl device."""
    kind, index = dlpack_device(source)
    producer = _Capsule(source, (kind, index)) if is_capsule(source) else source
    try:
        if kind in HOST_TYPES:
            host = np.from_dlpack(producer)
            if producer is not source and _capi.PyCapsule_IsValid(source, b"used_" + _LEGACY):
                host = _writable(host)
            return host, get_device("cpu")
        if kind in CUDA_TYPES:
            dev = cuda_device(index)
            with mem.scope(dev):  # CuPy hands the producer kdsl's stream to wait on
                return mem.cupy().from_dlpack(producer), dev
    except (BufferError, TypeError, ValueError, RuntimeError, NotImplementedError) as e:
        raise InteropTypeError(f"cannot import {_name(source)} through DLPack: {e}") from None
    raise InteropDeviceError(
        f"{_name(source)} lives on DLPack device type {kind}, which kdsl has no device for "
        f"(kdsl reads CPU and CUDA memory)"
    )


def _writable(host: np.ndarray) -> np.ndarray:
    """A writable alias of a host view NumPy made read-only.

    A legacy capsule has no read-only flag, so NumPy marks what it reads read-only
    to be safe; the producers that hand out legacy capsules (PyTorch, Paddle) give
    writable memory, and kernels write through the pointer anyway. The alias keeps
    the read-only view (and so the capsule's owner) alive.
    """
    if host.flags.writeable or host.size == 0:
        return host
    lo, hi = np.lib.array_utils.byte_bounds(host)
    raw = (ctypes.c_char * (hi - lo)).from_address(lo)
    raw.owner = host
    return np.ndarray(
        host.shape, host.dtype, buffer=raw, offset=host.ctypes.data - lo, strides=host.strides
    )


def _name(source: Any) -> str:
    return "a DLPack capsule" if is_capsule(source) else f"a {type(source).__name__}"


def export(buf: Any, device: Device, **kwargs: Any) -> Any:
    """``buf.__dlpack__(**kwargs)`` with the device's stream current (see the module doc)."""
    kwargs = {k: v for k, v in kwargs.items() if v is not None or k == "stream"}
    if device.is_cpu:
        return buf.__dlpack__(**kwargs)
    with mem.scope(device):
        return buf.__dlpack__(**kwargs)


class Exporter:
    """A DLPack producer over a kdsl buffer (a reinterpreted view of an array's ``_buf``)."""

    def __init__(self, buf: Any, device: Device) -> None:
        self.buf = buf
        self.device = device

    def __dlpack_device__(self) -> tuple[int, int]:
        return self.buf.__dlpack_device__()

    def __dlpack__(self, *, stream: Any = None, **kwargs: Any) -> Any:
        return export(self.buf, self.device, stream=stream, **kwargs)


def from_dlpack(source: Any, dtype: Any = None) -> array:
    """A ``kdsl.array`` sharing the memory of a DLPack producer or capsule (no copy).

    ``source`` is any object with ``__dlpack__`` (a PyTorch tensor, a JAX or CuPy
    array...) or a capsule from a ``to_dlpack`` function, legacy or versioned.
    ``dtype`` reads the data as another kdsl type: a vector or matrix dtype takes
    the trailing dims as components. For CUDA producers, the producer is asked to
    order its work before the current kdsl stream of the array's device.
    """
    if isinstance(source, array):
        return source if dtype is None else wrap(source._buf, dtype, source.device, "kdsl array")
    if not (is_capsule(source) or hasattr(source, "__dlpack__")):
        raise KdslError(
            f"from_dlpack() takes an object with __dlpack__ or a DLPack capsule, not "
            f"{type(source).__name__}"
        )
    buf, dev = buffer_from_dlpack(source)
    what = f"{buf.dtype.name} DLPack tensor of shape {tuple(buf.shape)}"
    return wrap(buf, dtype, dev, what)


def to_dlpack(wp_array: array, *, max_version: tuple[int, int] | None = None) -> Any:
    """A DLPack capsule sharing ``wp_array``'s memory (no copy, no stream synchronization).

    The capsule is legacy (``"dltensor"``) unless ``max_version=(1, 0)`` asks for a
    versioned one. A vector or matrix array gives a tensor with its component dims
    appended. The consumer must order its work after kdsl's on a GPU itself (see
    docs/interop.md); ``framework.from_dlpack(wp_array)`` does that for you.
    """
    if not isinstance(wp_array, array):
        raise KdslError(f"to_dlpack() takes a kdsl array, not {type(wp_array).__name__}")
    # stream=-1: the DLPack way to say "no synchronization" (CUDA producers only).
    stream = -1 if wp_array.device.is_cuda else None
    return export(wp_array._buf, wp_array.device, stream=stream, max_version=max_version)
