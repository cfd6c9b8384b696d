"""CUDA IPC: sharing arrays and events between processes on one host (Warp's API).

- ``array_ipc_handle(a)`` (``a.ipc_handle()``): the 64-byte ``cudaIpcMemHandle_t`` of
  the allocation behind ``a``. As in Warp, only arrays allocated directly with
  ``cudaMalloc`` qualify: allocate inside ``ScopedMempool(device, False)``. A handle
  names a whole allocation, so a view that does not start it, an array from the pool
  (CuPy's pool hands out parts of larger allocations), managed memory and memory kdsl
  did not allocate itself are refused with the reason.
- ``from_ipc_handle(handle, dtype, shape, strides=None, device=None)``: an array over
  the memory another process shared; the mapping is closed when the last array or view
  using it is gone.
- ``event_ipc_handle(e)`` (``Event(interprocess=True).ipc_handle()``) and
  ``event_from_ipc_handle(handle, device=None)``: the same for events, to order work
  across processes. A process cannot open its own handles (a CUDA rule).
"""

from __future__ import annotations

import sys
from typing import Any

import numpy as np

from kdsl.errors import KdslError
from kdsl.runtime.array import array
from kdsl.runtime.device import Device, cupy, get_device
from kdsl.runtime.dtypes import inner_shape, normalize_shape, np_dtype, resolve_dtype
from kdsl.runtime.stream import Event

_HANDLE_BYTES = 64  # CUDA_IPC_HANDLE_SIZE


def _ipc_device(device: Any, what: str) -> Device:
    dev = get_device(device)
    if not dev.is_cuda:
        raise KdslError(f"{what}: IPC shares CUDA memory only, not memory of '{dev}'")
    if not sys.platform.startswith("linux"):
        raise KdslError(f"{what}: CUDA IPC is supported on Linux only")
    return dev


def _check_handle(handle: Any, what: str) -> bytes:
    if not isinstance(handle, bytes | bytearray) or len(handle) != _HANDLE_BYTES:
        raise KdslError(f"{what}: an IPC handle is {_HANDLE_BYTES} bytes, got {handle!r:.60}")
    return bytes(handle)


def array_ipc_handle(arr: array) -> bytes:
    """The IPC handle of the ``cudaMalloc`` allocation that ``arr`` starts (Warp's
    ``array.ipc_handle()``)."""
    dev = _ipc_device(arr.device, "ipc_handle()")
    memory = cupy().cuda.memory
    buf = arr._buf
    owner = buf.data.mem
    if isinstance(owner, memory.PooledMemory):
        raise KdslError(
            f"ipc_handle(): the array was allocated from the memory pool of '{dev}'; allocate "
            f"it inside kdsl.ScopedMempool('{dev}', False) to share it between processes"
        )
    if type(owner) is not memory.Memory:  # managed, external or custom-allocated memory
        raise KdslError(
            "ipc_handle(): only arrays kdsl allocated with cudaMalloc can be shared (not "
            "managed memory, memory from a custom allocator or memory wrapped from elsewhere)"
        )
    if buf.data.ptr != owner.ptr:
        raise KdslError(
            "ipc_handle(): the array is a view that does not start its allocation; share the "
            "whole array and take the view in the other process"
        )
    rt = cupy().cuda.runtime
    with cupy().cuda.Device(dev.ordinal):
        return bytes(rt.ipcGetMemHandle(buf.data.ptr))


def _open(opener: str, handle: bytes, dev: Device, what: str, hint: str = "") -> int:
    """``cudaIpcOpen*Handle`` (``opener``, a CuPy runtime name) of ``handle`` on ``dev``;
    a KdslError naming ``what`` (and ``hint``) when CUDA refuses it."""
    cp = cupy()
    with cp.cuda.Device(dev.ordinal):
        try:
            return getattr(cp.cuda.runtime, opener)(handle)
        except cp.cuda.runtime.CUDARuntimeError as e:
            raise KdslError(
                f"{what}: CUDA could not open the handle on '{dev}'{hint}: {e}"
            ) from None


class _Opened:
    """A CUDA object opened from an IPC handle (``ptr`` on device ``ordinal``), released
    with the CuPy runtime function named ``release`` when collected."""

    release = ""

    def __init__(self, ptr: int, ordinal: int) -> None:
        self.ptr = ptr
        self.ordinal = ordinal

    def __del__(self) -> None:
        try:
            cp = cupy()
            with cp.cuda.Device(self.ordinal):
                getattr(cp.cuda.runtime, self.release)(self.ptr)
        except Exception:  # at interpreter exit CUDA may already be gone
            pass


class _Mapping(_Opened):
    """An opened IPC allocation; closed when the last buffer over it is collected."""

    release = "ipcCloseMemHandle"


def from_ipc_handle(
    handle: bytes, dtype: Any, shape: Any, strides: Any = None, device: Any = None
) -> array:
    """An array over memory another process shared with ``array.ipc_handle()``.

    ``strides`` are in bytes (contiguous when None); ``device`` is the CUDA device the
    memory lives on (the current CUDA device when None).
    """
    dev = _ipc_device("cuda" if device is None else device, "from_ipc_handle()")
    handle = _check_handle(handle, "from_ipc_handle()")
    t = resolve_dtype(dtype)
    dims = normalize_shape(shape)
    npd, inner = np_dtype(t), inner_shape(t)
    item = npd.itemsize * int(np.prod(inner, dtype=np.int64))
    if strides is None:
        outer = tuple(item * int(np.prod(dims[k + 1 :], dtype=np.int64)) for k in range(len(dims)))
    else:
        outer = tuple(int(s) for s in strides)
        if len(outer) != len(dims):
            raise KdslError(f"from_ipc_handle(): {len(outer)} strides for {len(dims)} dimensions")
    inner_strides = tuple(npd.itemsize * int(np.prod(inner[k + 1 :])) for k in range(len(inner)))
    extent = 0 if 0 in dims else item + sum((d - 1) * abs(s) for d, s in zip(dims, outer))
    ptr = _open("ipcOpenMemHandle", handle, dev, "from_ipc_handle()",
                " (a handle made in this same process, or one whose array was freed?)")  # fmt: skip
    cp = cupy()
    mem = cp.cuda.UnownedMemory(ptr, extent, _Mapping(ptr, dev.ordinal), dev.ordinal)
    buf = cp.ndarray(dims + inner, npd, cp.cuda.MemoryPointer(mem, 0), outer + inner_strides)
    return array(buf, dtype=dtype, device=dev, copy=False)


def event_ipc_handle(event: Event) -> bytes:
    """The IPC handle of an ``Event(interprocess=True)`` (Warp's ``Event.ipc_handle()``)."""
    _ipc_device(event.device, "Event.ipc_handle()")
    if not getattr(event, "interprocess", False):
        raise KdslError("Event.ipc_handle(): create the event with Event(interprocess=True)")
    with cupy().cuda.Device(event.device.ordinal):
        return bytes(cupy().cuda.runtime.ipcGetEventHandle(event.cuda_event))


class _OpenedEvent(_Opened):
    """The CuPy-event face (``ptr``, ``record``, ``synchronize``, ``done``) of an event
    opened from an IPC handle; destroyed when collected."""

    release = "eventDestroy"

    def record(self, stream: Any) -> None:
        cupy().cuda.runtime.eventRecord(self.ptr, stream.ptr)

    def synchronize(self) -> None:
        cupy().cuda.runtime.eventSynchronize(self.ptr)

    @property
    def done(self) -> bool:
        return cupy().cuda.runtime.eventQuery(self.ptr) == 0


def event_from_ipc_handle(handle: bytes, device: Any = None) -> Event:
    """An ``Event`` opened from another process's ``Event.ipc_handle()``, on ``device``
    (the current CUDA device when None): record it, wait on it, synchronize it."""
    dev = _ipc_device("cuda" if device is None else device, "event_from_ipc_handle()")
    handle = _check_handle(handle, "event_from_ipc_handle()")
    ptr = _open("ipcOpenEventHandle", handle, dev, "event_from_ipc_handle()")
    event = Event.__new__(Event)  # wraps the opened handle instead of creating an event
    event.cupy = _OpenedEvent(ptr, dev.ordinal)
    event.device = dev
    event.enable_timing = False
    event.interprocess = True
    return event
