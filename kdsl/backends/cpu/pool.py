"""A persistent thread pool that runs a kernel's thread range in chunks.

The kernel is a ctypes function pointer; ctypes releases the GIL around the
call, so chunks run truly in parallel. Launches smaller than ``min_parallel``
threads run inline on the calling thread (starting workers costs more than they
save). The worker count defaults to the CPUs this process may use and can be set
with ``set_num_threads`` or the ``KDSL_CPU_THREADS`` environment variable.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

RangeFn = Callable[[int, int], None]

_lock = threading.Lock()
_executor: ThreadPoolExecutor | None = None
_num_threads: int | None = None

#: Launches with fewer threads than this run on the calling thread.
min_parallel = 4096


def default_num_threads() -> int:
    """``KDSL_CPU_THREADS`` if set, else the number of CPUs this process may run on."""
    env = os.environ.get("KDSL_CPU_THREADS")
    if env:
        return max(1, int(env))
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def num_threads() -> int:
    """The number of threads launches use."""
    return _num_threads or default_num_threads()


def set_num_threads(n: int | None) -> None:
    """Use ``n`` threads from now on (None: the default); restarts the pool."""
    global _num_threads, _executor
    if n is not None and n < 1:
        raise ValueError(f"the number of threads must be at least 1, got {n}")
    with _lock:
        _num_threads = n
        if _executor is not None:
            _executor.shutdown(wait=True)
            _executor = None


def _pool(workers: int) -> ThreadPoolExecutor:
    global _executor
    with _lock:
        if _executor is None:
            _executor = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="kdsl-cpu")
        return _executor


def chunks(total: int, parts: int) -> list[tuple[int, int]]:
    """``[0, total)`` split into ``parts`` contiguous near-equal ranges (none empty)."""
    parts = max(1, min(parts, total))
    size, extra = divmod(total, parts)
    out, start = [], 0
    for p in range(parts):
        end = start + size + (1 if p < extra else 0)
        out.append((start, end))
        start = end
    return out


def run(fn: RangeFn, total: int, threads: int | None = None) -> None:
    """Run ``fn(start, end)`` over ``[0, total)``, split over the pool's threads."""
    if total <= 0:
        return
    n = threads or num_threads()
    if n == 1 or total < min_parallel:
        fn(0, total)
        return
    ranges = chunks(total, n)
    pool = _pool(n - 1 if n > 1 else 1)
    futures = [pool.submit(fn, s, e) for s, e in ranges[1:]]
    fn(*ranges[0])  # the calling thread takes a share too
    for f in futures:
        f.result()
