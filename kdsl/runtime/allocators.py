"""Warp's allocator API over kdsl's memory: NumPy on the cpu, CuPy on CUDA devices.

An allocator is any object with ``allocate(size_in_bytes) -> int`` (a device pointer)
and ``deallocate(ptr, size_in_bytes)`` (Warp's ``Allocator`` protocol). By default a
CUDA device allocates from CuPy's memory pool (``CupyPoolAllocator``; see
``kdsl.runtime.mempool`` for pooling on/off) and the cpu from NumPy
(``HostAllocator``). ``set_device_allocator(device, a)`` makes that CUDA device's new
buffers come from ``a``: kdsl wraps the pointer as CuPy memory it does not own and
calls ``a.deallocate`` when the last array over it dies. Custom allocators are for
CUDA devices only, as in Warp.

``MemoryKind`` classifies what backs an array (``memory_kind_of``), and
``can_access(device, array)`` answers from it.
"""

from __future__ import annotations

import contextlib
import enum
from typing import Any, Protocol, runtime_checkable

import numpy as np

from kdsl.errors import KdslError, KdslTypeError
from kdsl.runtime import memory_tracker as tracker
from kdsl.runtime.device import Device, cupy, get_cuda_devices, get_device


@runtime_checkable
class Allocator(Protocol):
    """What kdsl (and Warp) accepts as a memory allocator."""

    def allocate(self, size_in_bytes: int) -> int:
        """Allocate ``size_in_bytes`` and return the pointer as an int."""
        ...

    def deallocate(self, ptr: int, size_in_bytes: int) -> None:
        """Free memory that ``allocate`` returned."""
        ...


class MemoryKind(enum.IntEnum):
    """The kind of memory observed behind an array (Warp's values)."""

    UNKNOWN = 0
    HOST = 1
    PINNED = 2
    CUDA_DEVICE = 3
    CUDA_MEMPOOL = 4
    CUDA_MANAGED = 5


class HostAllocator:
    """The cpu's allocator: NumPy buffers, kept alive here until ``deallocate``."""

    memory_kind = MemoryKind.HOST

    def __init__(self) -> None:
        self._live: dict[int, np.ndarray] = {}

    def allocate(self, size_in_bytes: int) -> int:
        """A new host buffer of ``size_in_bytes``; its address."""
        buf = np.empty(max(int(size_in_bytes), 1), np.uint8)
        self._live[buf.ctypes.data] = buf
        return buf.ctypes.data

    def deallocate(self, ptr: int, size_in_bytes: int) -> None:
        """Release the buffer at ``ptr``."""
        self._live.pop(ptr, None)


class CupyPoolAllocator:
    """A CUDA device's built-in allocator: CuPy's allocator (its memory pool unless
    ``set_mempool_enabled(device, False)``), on whichever CUDA device is current."""

    memory_kind = MemoryKind.CUDA_DEVICE

    def __init__(self) -> None:
        self._live: dict[int, Any] = {}

    def allocate(self, size_in_bytes: int) -> int:
        """``size_in_bytes`` from CuPy on the current device; the device pointer."""
        mp = cupy().cuda.alloc(int(size_in_bytes))
        self._live[mp.ptr] = mp
        return int(mp.ptr)

    def deallocate(self, ptr: int, size_in_bytes: int) -> None:
        """Give the block at ``ptr`` back to CuPy."""
        self._live.pop(ptr, None)


class CudaManagedAllocator:
    """Allocates CUDA managed (unified) memory, accessible from the host and every GPU
    (``cudaMallocManaged``); usable on any CUDA device."""

    memory_kind = MemoryKind.CUDA_MANAGED

    def allocate(self, size_in_bytes: int) -> int:
        """``size_in_bytes`` of managed memory; the pointer."""
        rt = cupy().cuda.runtime
        # CuPy names the flag cudaMemAttachGlobal (1 in the CUDA headers).
        flag = getattr(rt, "cudaMemAttachGlobal", 1)
        return int(rt.mallocManaged(max(int(size_in_bytes), 1), flag))

    def deallocate(self, ptr: int, size_in_bytes: int) -> None:
        """``cudaFree`` the block at ``ptr``."""
        cupy().cuda.runtime.free(ptr)


_HOST = HostAllocator()
_POOL = CupyPoolAllocator()
#: Custom allocators by CUDA ordinal.
_CUSTOM: dict[int, Any] = {}


def _check(allocator: Any) -> None:
    if allocator is None:
        return
    if not (callable(getattr(allocator, "allocate", None))
            and callable(getattr(allocator, "deallocate", None))):  # fmt: skip
        raise KdslTypeError(
            "allocator must implement the Allocator protocol (allocate(size_in_bytes) -> int, "
            f"deallocate(ptr, size_in_bytes) -> None), got {type(allocator).__name__}"
        )


def set_device_allocator(device: Any, allocator: Allocator | None) -> None:
    """Make new buffers on CUDA ``device`` come from ``allocator`` (None: the built-in)."""
    dev = get_device(device)
    if not dev.is_cuda:
        raise KdslError(f"custom allocators are supported on CUDA devices only, not on '{dev}'")
    _check(allocator)
    if allocator is None:
        _CUSTOM.pop(dev.ordinal, None)
    else:
        _CUSTOM[dev.ordinal] = allocator


def set_cuda_allocator(allocator: Allocator | None) -> None:
    """``set_device_allocator`` for every CUDA device (None: the built-in ones)."""
    _check(allocator)
    devices = get_cuda_devices()
    if not devices:
        raise KdslError("set_cuda_allocator: no CUDA devices available")
    for d in devices:
        set_device_allocator(d, allocator)


def get_device_allocator(device: Any) -> Allocator:
    """The allocator new buffers on ``device`` come from."""
    dev = get_device(device)
    if dev.is_cpu:
        return _HOST
    return _CUSTOM.get(dev.ordinal, _POOL)


class ScopedAllocator:
    """``with ScopedAllocator(device, allocator):`` a custom allocator for a block."""

    def __init__(self, device: Any, allocator: Allocator | None) -> None:
        self.device = get_device(device)
        _check(allocator)
        self.allocator = allocator

    def __enter__(self) -> ScopedAllocator:
        self.saved = _CUSTOM.get(self.device.ordinal) if self.device.is_cuda else None
        set_device_allocator(self.device, self.allocator)
        return self

    def __exit__(self, *exc_info: object) -> None:
        set_device_allocator(self.device, self.saved)


class _Owner:
    """Owns one block: gives it back (and notes the free) when CuPy drops the memory."""

    __slots__ = ("allocator", "ptr", "nbytes", "token", "kind", "keep")

    def __init__(self, allocator: Any, ptr: int, nbytes: int, token: int | None,
                 keep: Any = None) -> None:  # fmt: skip
        self.allocator, self.ptr, self.nbytes, self.token = allocator, ptr, nbytes, token
        self.kind = getattr(allocator, "memory_kind", MemoryKind.UNKNOWN)
        self.keep = keep

    def __del__(self) -> None:
        if self.token is not None:
            tracker.note_free(self.token)
        if self.allocator is not None:
            with contextlib.suppress(Exception):  # a finalizer must not raise
                self.allocator.deallocate(self.ptr, self.nbytes)


#: Owners of live custom/tracked blocks by pointer (for ``memory_kind_of``).
_OWNERS: dict[int, Any] = {}


def cuda_empty(shape: tuple[int, ...], dtype: Any, device: Device, nbytes: int) -> Any:
    """An uninitialized CuPy buffer on ``device`` (current): from its custom allocator if
    one is set, else CuPy's; recorded when a memory tracker is active."""
    cp = cupy()
    custom = _CUSTOM.get(device.ordinal)
    if custom is None and not tracker.active():
        return cp.empty(shape, dtype)
    token = tracker.note_alloc(nbytes, device) if tracker.active() else None
    if custom is None:  # tracked only: CuPy's block, freed through the owner
        mp = cp.cuda.alloc(nbytes)
        owner = _Owner(None, mp.ptr, nbytes, token, keep=mp)
        owner.kind = MemoryKind.CUDA_DEVICE
    else:
        ptr = int(custom.allocate(nbytes))
        if not ptr and nbytes:
            raise KdslError(f"the custom allocator of '{device}' returned a null pointer for "
                            f"{nbytes} bytes")  # fmt: skip
        owner = _Owner(custom, ptr, nbytes, token)
    mem = cp.cuda.UnownedMemory(owner.ptr, nbytes, owner, device_id=device.ordinal)
    return cp.ndarray(shape, dtype, memptr=cp.cuda.MemoryPointer(mem, 0))


def host_empty(shape: tuple[int, ...], dtype: Any, device: Device) -> np.ndarray:
    """An uninitialized NumPy buffer; recorded when a memory tracker is active."""
    buf = np.empty(shape, dtype)
    if tracker.active():
        import weakref

        weakref.finalize(buf, tracker.note_free, tracker.note_alloc(buf.nbytes, device))
    return buf


def memory_kind_of(arr: Any) -> MemoryKind:
    """What backs the array ``arr``: HOST (or PINNED) on the cpu; on CUDA, what the driver
    reports for its pointer (managed memory is CUDA_MANAGED; CuPy's pool is plain device
    memory, CUDA_DEVICE, not a CUDA stream-ordered mempool)."""
    dev = arr.device
    if dev.is_cpu:
        return MemoryKind.HOST  # kdsl's host arrays are NumPy memory (pinned is not honoured)
    rt = cupy().cuda.runtime
    try:
        attrs = rt.pointerGetAttributes(arr.ptr)
    except Exception:
        return MemoryKind.UNKNOWN
    if attrs.type == 3:  # cudaMemoryTypeManaged
        return MemoryKind.CUDA_MANAGED
    if attrs.type == 2:  # cudaMemoryTypeDevice
        return MemoryKind.CUDA_DEVICE
    if attrs.type == 1:  # cudaMemoryTypeHost (pinned)
        return MemoryKind.PINNED
    return MemoryKind.UNKNOWN


def can_access(device: Any, resource: Any) -> bool:
    """Whether kernels on ``device`` can read and write the array ``resource`` directly."""
    from kdsl.runtime.array import array
    from kdsl.runtime.indexed import indexedarray

    dev = get_device(device)
    if isinstance(resource, indexedarray):
        return can_access(dev, resource.data) and all(
            i is None or can_access(dev, i) for i in resource.indices
        )
    if not isinstance(resource, array):
        raise KdslTypeError(f"can_access takes a kdsl array, not {type(resource).__name__}")
    if resource.device == dev:
        return True
    kind = memory_kind_of(resource)
    if kind == MemoryKind.CUDA_MANAGED:
        return True
    if dev.is_cpu:
        return False
    # Another GPU's memory (cudaMalloc blocks, pooled or not): reachable through peer
    # access, which set_peer_access_enabled or set_mempool_access_enabled switch on.
    from kdsl.runtime.peer import is_mempool_access_enabled, is_peer_access_enabled

    owner = resource.device
    return is_peer_access_enabled(owner, dev) or is_mempool_access_enabled(owner, dev)
