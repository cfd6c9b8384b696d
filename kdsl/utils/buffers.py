"""What the parallel primitives share: zero-copy views of kdsl arrays, and host threads.

Each primitive works on the array's own buffer through the array module of its device
(NumPy on the CPU, CuPy on a CUDA device, which runs CUB's scans, sorts and
reductions); on the CPU the large ones split the work over the host's cores, since
NumPy releases the GIL inside these loops.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from functools import cache
from typing import Any

import numpy as np

from kdsl.errors import KdslError
from kdsl.runtime import cuda_memory
from kdsl.runtime.array import array

#: Below this many elements one thread is faster than handing work to the pool.
PARALLEL_MIN = 1 << 16


class UtilsError(KdslError, RuntimeError):
    """A bad argument to a ``kdsl.utils`` primitive (a ``RuntimeError`` too, as in Warp)."""


def check_array(name: str, a: Any) -> array:
    """``a`` if it is a kdsl array, else a ``UtilsError`` naming the parameter."""
    if not isinstance(a, array):
        raise UtilsError(f"{name} must be a kdsl array, got {type(a).__name__}")
    return a


def same_device(**arrays: array | None) -> None:
    """Refuse arrays that live on different devices, naming them."""
    given = {n: a for n, a in arrays.items() if a is not None}
    devices = {str(a.device) for a in given.values()}
    if len(devices) > 1:
        where = ", ".join(f"{n} on '{a.device}'" for n, a in given.items())
        raise UtilsError(f"the arrays must live on one device: {where}")


def device_buffer(a: array) -> tuple[Any, Any]:
    """``(xp, buffer)``: the array module of ``a``'s device (NumPy or CuPy) and a zero-copy,
    writable view of ``a`` with the element dims appended."""
    xp = cuda_memory.xp(a.device)
    if a.device.is_cpu:
        return xp, np.asarray(a)
    # With the array's device current: CuPy copies an interface object of another
    # device onto the current one, so with cuda:1 current a sort of a cuda:0 array
    # sorted a copy and left the array as it was.
    with xp.cuda.Device(a.device.ordinal):
        return xp, xp.asarray(a)


def flat_view(a: array, name: str) -> tuple[Any, Any]:
    """``(xp, view)``: like ``device_buffer``, shaped ``(a.size, *element_dims)``."""
    if not a.is_contiguous and a.ndim != 1:
        raise UtilsError(f"{name} must be contiguous or one-dimensional")
    xp, buf = device_buffer(a)
    inner = buf.shape[a.ndim :]
    return xp, buf.reshape((a.size, *inner)) if a.is_contiguous else buf


def on_device(a: array) -> cuda_memory.scope:
    """The context in which CuPy work on ``a`` runs on its device and kdsl stream."""
    return cuda_memory.scope(a.device)


@cache
def host_threads() -> int:
    """Threads the CPU primitives use: the cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not every OS has affinity masks
        return max(1, os.cpu_count() or 1)


@cache
def _pool(n: int) -> ThreadPoolExecutor:
    return ThreadPoolExecutor(max_workers=n, thread_name_prefix="kdsl-utils")


def chunks(n: int) -> list[tuple[int, int]]:
    """``[start, end)`` ranges splitting ``n`` items over the host threads (one if small)."""
    k = host_threads() if n >= PARALLEL_MIN else 1
    bounds = [n * i // k for i in range(k + 1)]
    return [(bounds[i], bounds[i + 1]) for i in range(k)]


def run_parallel(fn: Callable[..., Any], ranges: Sequence[tuple[int, int]]) -> list[Any]:
    """``fn(start, end)`` for each range, on the host threads; results in range order."""
    if len(ranges) == 1:
        return [fn(*ranges[0])]
    return list(_pool(len(ranges)).map(lambda r: fn(*r), ranges))
