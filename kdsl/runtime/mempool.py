"""Warp's memory-pool API over CuPy's memory pool (the pool kdsl's CUDA arrays come from).

- ``is_mempool_supported``/``is_mempool_enabled``: True for CUDA devices (pooling is
  on by default), False for the CPU, as in Warp.
- ``set_mempool_enabled(device, False)`` makes that device's new allocations go
  straight to ``cudaMalloc`` (freed when the array dies); CuPy's allocator is
  process-wide, so kdsl installs one allocator that asks, per allocation, whether
  the current device pools.
- ``set_mempool_release_threshold(device, t)``: the free memory the pool may keep
  cached. Each time ``kdsl.synchronize``/``synchronize_device`` runs (and when the
  threshold is set) a pool holding more free memory than ``t`` returns all its free
  blocks to the driver (CuPy releases whole pools, not parts). The default keeps
  every block (CuPy's behaviour): ``get_mempool_release_threshold`` reports 2**64-1.
- ``get_mempool_used_mem_current``/``high``: bytes held by live arrays, and the most
  held at once since the process started, as kdsl allocations saw it.

Asking these of the CPU is an error, as in Warp.
"""

from __future__ import annotations

from typing import Any

from kdsl.errors import KdslError
from kdsl.runtime.device import Device, cupy, get_device

NO_RELEASE = 2**64 - 1

#: Release thresholds set per CUDA ordinal (absent: keep every block).
THRESHOLDS: dict[int, int] = {}
_disabled: set[int] = set()
_high: dict[int, int] = {}


def _cuda(device: Any, what: str) -> Device:
    dev = get_device(device)
    if not dev.is_cuda:
        raise KdslError(f"{what}: memory pools exist on CUDA devices only, not on '{dev}'")
    return dev


def _pool() -> Any:
    return cupy().get_default_memory_pool()


def is_mempool_supported(device: Any) -> bool:
    """True for CUDA devices (CuPy's pool), False for the CPU."""
    return get_device(device).is_cuda


def is_mempool_enabled(device: Any) -> bool:
    """Whether new allocations on ``device`` come from the pool (False for the CPU)."""
    dev = get_device(device)
    return dev.is_cuda and dev.ordinal not in _disabled


def _allocate(size: int) -> Any:
    cp = cupy()
    if cp.cuda.runtime.getDevice() in _disabled:
        return cp.cuda.memory.MemoryPointer(cp.cuda.memory.Memory(size), 0)
    return _pool().malloc(size)


def set_mempool_enabled(device: Any, enable: bool) -> None:
    """Pool (True) or not (False) the new allocations on ``device``.

    Enabling on the CPU is an error; disabling there does nothing (Warp's rules).
    """
    dev = get_device(device)
    if not dev.is_cuda:
        if enable:
            raise KdslError(f"set_mempool_enabled: memory pools exist on CUDA devices only, "
                            f"not on '{dev}'")  # fmt: skip
        return
    cp = cupy()
    (_disabled.discard if enable else _disabled.add)(dev.ordinal)
    cp.cuda.set_allocator(_allocate if _disabled else _pool().malloc)


def set_mempool_release_threshold(device: Any, threshold: int | float) -> None:
    """Free memory (bytes) the pool of ``device`` may keep; 0 < t <= 1 is a fraction of
    the device's memory, as in Warp."""
    dev = _cuda(device, "set_mempool_release_threshold")
    if isinstance(threshold, bool) or not isinstance(threshold, int | float):
        raise KdslError(f"set_mempool_release_threshold: threshold must be a number of bytes "
                        f"or a fraction, not {threshold!r}")  # fmt: skip
    if threshold < 0:
        threshold = 0
    elif 0 < threshold <= 1:
        threshold = int(threshold * dev.total_memory)
    THRESHOLDS[dev.ordinal] = int(threshold)
    trim(dev.ordinal)


def get_mempool_release_threshold(device: Any = None) -> int:
    """The release threshold of ``device`` in bytes (2**64-1 when none was set)."""
    return THRESHOLDS.get(_cuda(device, "get_mempool_release_threshold").ordinal, NO_RELEASE)


def _used(ordinal: int) -> int:
    cp = cupy()
    with cp.cuda.Device(ordinal):
        return int(_pool().used_bytes())


def get_mempool_used_mem_current(device: Any = None) -> int:
    """Bytes of the pool of ``device`` held by live allocations."""
    return _used(_cuda(device, "get_mempool_used_mem_current").ordinal)


def get_mempool_used_mem_high(device: Any = None) -> int:
    """The most bytes of the pool of ``device`` held at once (by kdsl's allocations)."""
    ordinal = _cuda(device, "get_mempool_used_mem_high").ordinal
    return max(_high.get(ordinal, 0), _used(ordinal))


def note_allocation(ordinal: int) -> None:
    """Update the high-water mark of ``ordinal`` (``cuda_memory.empty`` calls it, with
    the device current)."""
    used = int(_pool().used_bytes())
    if used > _high.get(ordinal, 0):
        _high[ordinal] = used


def trim(ordinal: int) -> None:
    """Release the free blocks of ``ordinal``'s pool if they exceed its threshold."""
    limit = THRESHOLDS.get(ordinal)
    if limit is None:
        return
    cp = cupy()
    with cp.cuda.Device(ordinal):
        pool = _pool()
        if pool.total_bytes() - pool.used_bytes() > limit:
            pool.free_all_blocks()


def trim_all() -> None:
    """``trim`` every device with a threshold (after a synchronize)."""
    for ordinal in list(THRESHOLDS):
        trim(ordinal)


class ScopedMempool:
    """``with ScopedMempool(device, enable):`` pools (or not) allocations for a block."""

    def __init__(self, device: Any, enable: bool) -> None:
        self.device = get_device(device)
        self.enable = enable

    def __enter__(self) -> ScopedMempool:
        self.saved = is_mempool_enabled(self.device)
        set_mempool_enabled(self.device, self.enable)
        return self

    def __exit__(self, *exc_info: object) -> None:
        set_mempool_enabled(self.device, self.saved)
