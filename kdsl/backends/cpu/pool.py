"""A persistent thread pool that runs a kernel's thread range in chunks.

Two pools serve it: the native pool (``native_pool``: workers parked in native code,
a launch handed over without Python), used for native range functions once its
runtime is loaded (``install_native``), and Python worker threads fed through queues,
used otherwise (``KDSL_CPU_POOL=python``, a kernel that prints, a launch made while
another thread's holds the native pool). The kernel is a ctypes function pointer;
ctypes releases the GIL around the call, so chunks run truly in parallel. The worker count defaults to the CPUs this
process may use and can be set with ``set_num_threads`` or the
``KDSL_CPU_THREADS`` environment variable.

Whether a launch goes to the pool is decided by measurement, not by a fixed size:
handing a launch to the workers costs a fixed time (measured once, when the pool
starts: ``dispatch_seconds``), and each kernel's cost per thread is measured on
its own inline launches (``RangeCost``). A launch runs on the pool when its
expected inline time exceeds what splitting it saves, ``t > overhead * n/(n-1)``
for ``n`` threads, where ``overhead`` is what the kernel's own pool launches were
measured to cost beyond their share of the work (``dispatch_seconds`` until one
ran): some launches pay far more on the pool than the hand-off, when the workers
went to sleep (a worker polls ``native_pool.WORKER_SPIN`` yields after its share, then
sleeps on a futex, and waking an idle vCPU takes tens of microseconds). That is the
likely cause of the ``throw`` scene's 4,096-thread adjoint launches costing about
100 us more on the pool than inline: they came some 70 us of Python apart (the adjoint
launch path before its plan and reuse), past the workers' polling, where forward
launches came 20 us apart; ``benchmarks/bench_pool_wake.py`` shows a launch's pool
cost growing with the pause before it (measured on a loaded host only). A kernel held inline
that way tries the pool again every ``retry_pool_every`` launches, so one slow pool
launch (the workers' start, a busy moment) does not decide for good. A kernel not measured
yet runs inline (and is measured) up to ``measure_inline_up_to`` threads, and on
the pool above it. ``benchmarks/bench_launch.py`` shows the
crossover for a cheap and a heavy kernel. ``adaptive = False`` restores a plain
size threshold (``min_parallel``), which tests use to force either path.
"""

from __future__ import annotations

import os
import queue
import threading
import time
from collections.abc import Callable
from typing import Any

from kdsl.backends.cpu.native_pool import NativePool

RangeFn = Callable[[int, int], None]

_lock = threading.Lock()
_workers: list[_Worker] = []
_num_threads: int | None = None
#: The native pool (``native_pool``), once its runtime is loaded; else launches use the
#: Python workers.
_native: NativePool | None = None

#: Kernels whose cost is not measured yet run inline below this many threads; with
#: ``adaptive = False`` it is the only rule.
min_parallel = 4096
#: Decide inline versus pool from measured costs (see the module docstring).
adaptive = True
_dispatch_seconds: float | None = None


#: A kernel held inline by its measured pool overhead tries the pool again on every
#: this-many-th launch (the overhead is a running estimate: slow launches age out).
retry_pool_every = 16
#: A kernel not measured yet runs inline once (to be measured) up to this many threads,
#: even above ``min_parallel``: its pool launches are then chosen from its cost.
measure_inline_up_to = 1 << 16


class RangeCost:
    """The measured costs of one kernel (running estimates): per thread on its inline
    launches, and what a launch on the pool costs beyond its share of that work."""

    __slots__ = ("held_inline", "pool_overhead", "seconds_per_thread")

    def __init__(self) -> None:
        self.seconds_per_thread: float | None = None
        #: Seconds a pool launch took beyond ``seconds_per_thread * threads / workers``;
        #: None until a pool launch of a measured kernel (``dispatch_seconds`` stands in).
        self.pool_overhead: float | None = None
        #: Launches kept inline only by ``pool_overhead`` since the pool was last tried.
        self.held_inline = 0

    def record(self, seconds: float, threads: int) -> None:
        """Fold one inline launch of ``threads`` threads taking ``seconds`` into the estimate."""
        per = seconds / threads
        old = self.seconds_per_thread
        self.seconds_per_thread = per if old is None else 0.5 * (old + per)

    def record_pool(self, seconds: float, threads: int, workers: int) -> None:
        """Fold one pool launch over ``workers`` threads into ``pool_overhead``: a kernel
        whose pool launches cost more than the model's hand-off (page faults, memory
        traffic, the workers' wake-up) then stays inline where that is faster."""
        if self.seconds_per_thread is None:
            return
        extra = max(0.0, seconds - self.seconds_per_thread * threads / workers)
        old = self.pool_overhead
        # A cheaper launch replaces the estimate: the pool has shown it can do that, and
        # a dear one is often the host's doing (a busy moment). Averaging it in instead
        # kept kernels inline for several retries after one slow launch (cloth at 1.0x
        # Warp instead of 1.9x in about half of the scene benchmark's runs).
        self.pool_overhead = extra if old is None or extra < old else 0.5 * (old + extra)


class _Worker:
    """A daemon thread that runs ``(fn, start, end, done)`` tasks from its own queue.

    One ``SimpleQueue`` per worker and one per launch for completions: both are
    implemented in C, so handing out a launch costs a few microseconds, a fraction
    of what ``concurrent.futures`` spends on its futures and locks.
    """

    def __init__(self, index: int) -> None:
        self.tasks: queue.SimpleQueue = queue.SimpleQueue()
        self.thread = threading.Thread(target=self._loop, name=f"kdsl-cpu-{index}", daemon=True)
        self.thread.start()

    def _loop(self) -> None:
        while True:
            task = self.tasks.get()
            if task is None:
                return
            fn, start, end, done = task
            try:
                fn(start, end)
            except BaseException as e:  # handed to the launching thread, which re-raises
                done.put(e)
            else:
                done.put(None)


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
    global _num_threads
    if _num_threads is None:  # read the environment once: launches ask every time
        _num_threads = default_num_threads()
    return _num_threads


def set_num_threads(n: int | None) -> None:
    """Use ``n`` threads from now on (None: the default); restarts the pool."""
    global _num_threads, _dispatch_seconds
    if n is not None and n < 1:
        raise ValueError(f"the number of threads must be at least 1, got {n}")
    if _native is not None:
        _native.stop()
    with _lock:
        _num_threads = n if n is not None else default_num_threads()
        _dispatch_seconds = None  # measured again for the new thread count
        for w in _workers:
            w.tasks.put(None)  # finishes its queued work first, then exits
        _workers.clear()


def _pool(count: int) -> list[_Worker]:
    """At least ``count`` workers (started on first use)."""
    with _lock:
        while len(_workers) < count:
            _workers.append(_Worker(len(_workers)))
        return _workers


def _after_fork_in_child() -> None:
    """The child of a ``fork`` has none of the parent's worker threads: start afresh."""
    global _lock
    _lock = threading.Lock()
    _workers.clear()
    if _native is not None:
        _native.forget_threads()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_after_fork_in_child)


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


def install_native(pool: NativePool | None) -> None:
    """Hand native-code launches to ``pool`` from now on (None: the Python workers)."""
    global _native, _dispatch_seconds
    old, _native = _native, pool
    _dispatch_seconds = None  # measured again for the new pool
    if old is not None and old is not pool:
        old.stop()


def native() -> NativePool | None:
    """The native pool launches use, or None (the Python workers)."""
    return _native


def dispatch_seconds() -> float:
    """The measured time to hand a launch to the pool and collect it (median of 7)."""
    global _dispatch_seconds
    if _dispatch_seconds is None:
        n = num_threads()
        samples = []
        for _ in range(7):
            t0 = time.perf_counter()
            if _native is not None:
                _native.run(_native.noop, n, 0, 0, n)
            else:
                run(_nothing, n, n, force=True)
            samples.append(time.perf_counter() - t0)
        _dispatch_seconds = sorted(samples)[len(samples) // 2]
    return _dispatch_seconds


def _nothing(start: int, end: int) -> None:
    """The empty range function ``dispatch_seconds`` times."""


def run_range(
    fn: Callable[..., None],
    total: int,
    *args: Any,
    cost: RangeCost | None = None,
    address: int | None = None,
    whole: Callable[[], None] | None = None,
) -> None:
    """Run the native range function ``fn(start, end, *args)`` over ``[0, total)``.

    The launch path's entry: a launch that stays on the calling thread calls ``fn``
    directly, timed into ``cost`` (the kernel's measured cost) when given. ``address``
    is ``fn``'s native address (``args`` then being its two pointers): with it a launch
    split over threads goes to the native pool when there is one. ``whole``, when
    given, runs the whole range on the calling thread in place of ``fn(0, total, *args)``
    (a prepared launch's one-argument native call).
    """
    n = num_threads()
    if n == 1 or total < 2:
        if whole is None:
            fn(0, total, *args)
        else:
            whole()
        return
    measured = cost is not None and adaptive
    per = cost.seconds_per_thread if measured else None
    if per is None:  # not measured: small or first launches run inline (and are measured)
        inline = total < min_parallel or (measured and total <= measure_inline_up_to)
    else:
        inline = per * total <= dispatch_seconds() * n / (n - 1)
        if not inline and cost.pool_overhead is not None:
            inline = per * total <= cost.pool_overhead * n / (n - 1)
            # Held inline by a measured overhead: try the pool again now and then, so
            # one slow pool launch (the workers' start, a busy host) is not final.
            cost.held_inline = cost.held_inline + 1 if inline else 0
            if cost.held_inline >= retry_pool_every:
                inline, cost.held_inline = False, 0
    if not inline:
        t0 = time.perf_counter()
        if address is None or _native is None or not _native.run(address, total, *args, n):
            run(lambda s, e: fn(s, e, *args), total, force=True)
        if measured:
            cost.record_pool(time.perf_counter() - t0, total, n)
    elif whole is not None:
        t0 = time.perf_counter()
        whole()
        if cost is not None:
            cost.record(time.perf_counter() - t0, total)
    elif cost is None:
        fn(0, total, *args)
    else:
        t0 = time.perf_counter()
        fn(0, total, *args)
        cost.record(time.perf_counter() - t0, total)


def run(fn: RangeFn, total: int, threads: int | None = None, force: bool = False) -> None:
    """Run ``fn(start, end)`` over ``[0, total)``, split over the pool's threads.

    Below ``min_parallel`` threads it runs inline unless ``force`` is set.
    """
    if total <= 0:
        return
    n = threads or num_threads()
    if n == 1 or (total < min_parallel and not force):
        fn(0, total)
        return
    ranges = chunks(total, n)
    workers = _pool(len(ranges) - 1)
    done: queue.SimpleQueue = queue.SimpleQueue()
    for w, (s, e) in zip(workers, ranges[1:]):
        w.tasks.put((fn, s, e, done))
    error: BaseException | None = None
    try:
        fn(*ranges[0])  # the calling thread takes a share too
    except BaseException as e:
        error = e
    for _ in ranges[1:]:  # always wait: the workers may still be writing the arrays
        failed = done.get()
        if error is None and failed is not None:
            error = failed
    if error is not None:
        raise error
