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
its own launches (``RangeCost``: the minimum over its last ``cost_window``, so a
launch the host slowed down does not count). A launch runs on the pool when its
expected inline time exceeds what splitting it saves, ``t > overhead * n/(n-1)``
for ``n`` threads, where ``overhead`` is what the kernel's own pool launches were
measured to cost beyond their share of the work (``dispatch_seconds`` until one
ran), with ``hysteresis`` around that line: some launches pay far more on the pool than the hand-off, when the workers
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
from collections import deque
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
#: A kernel's costs are the minimum over this many last measurements (``RangeCost``).
cost_window = 8
#: The inline-or-pool line's hysteresis factor (``RangeCost.runs_inline``).
hysteresis = 1.25


class RangeCost:
    """The measured costs of one kernel, and its inline-or-pool choice (``runs_inline``).

    Each cost is the minimum over the last ``cost_window`` measurements: a launch
    slowed by the host (another process on the core, a worker woken late) says nothing
    about the kernel, and one such launch no longer moves the choice (a running mean
    did: one slow inline launch of a 5 us kernel sent it to the pool, where it stayed,
    since pool launches were never compared with the inline cost again). A pool launch
    also bounds the inline cost from above (``workers`` times its time), so such an
    estimate comes back down. Setting ``seconds_per_thread`` or ``pool_overhead``
    replaces its measurements with that one value (tests inject costs that way).
    """

    __slots__ = ("_bound", "_extra", "_over", "_per", "_spt", "held_inline", "on_pool")

    def __init__(self) -> None:
        #: Seconds per thread of inline launches, and the bounds pool launches put on it.
        self._per: deque[float] = deque(maxlen=cost_window)
        self._bound: deque[float] = deque(maxlen=cost_window)
        #: Seconds a pool launch took beyond ``seconds_per_thread * threads / workers``.
        self._extra: deque[float] = deque(maxlen=cost_window)
        #: ``seconds_per_thread`` and ``pool_overhead``, kept as measurements come (every
        #: launch reads them; a minimum is recomputed only when the one it was leaves).
        self._spt: float | None = None
        self._over: float | None = None
        #: Launches kept inline only by ``pool_overhead`` since the pool was last tried.
        self.held_inline = 0
        #: Whether the last choice was the pool (the threshold's hysteresis side).
        self.on_pool = False

    @property
    def seconds_per_thread(self) -> float | None:
        """Seconds per thread of an inline launch (None until one was measured)."""
        return self._spt

    @seconds_per_thread.setter
    def seconds_per_thread(self, value: float) -> None:
        self._per.clear()
        self._bound.clear()
        self._per.append(value)
        self._spt = value

    @property
    def pool_overhead(self) -> float | None:
        """Seconds a pool launch costs beyond its share of the work; None until one of a
        measured kernel ran (``dispatch_seconds`` stands in)."""
        return self._over

    @pool_overhead.setter
    def pool_overhead(self, value: float) -> None:
        self._extra.clear()
        self._extra.append(value)
        self._over = value

    def record(self, seconds: float, threads: int) -> None:
        """Add one inline launch of ``threads`` threads taking ``seconds``."""
        per, x, spt = self._per, seconds / threads, self._spt
        if spt is None or (len(per) == per.maxlen and per[0] <= spt):
            per.append(x)  # the minimum may leave the window: recompute it
            self._spt = min(min(per), min(self._bound)) if self._bound else min(per)
        else:
            per.append(x)
            if x < spt:
                self._spt = x

    def record_pool(self, seconds: float, threads: int, workers: int) -> None:
        """Add one pool launch over ``workers`` threads: what it cost beyond its share of
        the work (page faults, memory traffic, the workers' wake-up), so a kernel whose
        pool launches cost more stays inline where that is faster, and the bound it puts
        on the inline cost (each worker ran at most ``seconds`` of it)."""
        per = self._spt
        if per is None:
            return
        self._extra.append(max(0.0, seconds - per * threads / workers))
        self._over = min(self._extra)
        self._bound.append(seconds * workers / threads)
        self._spt = min(min(self._per), min(self._bound))

    def runs_inline(self, total: int, threads: int, dispatch: float) -> bool:
        """Whether a measured kernel's launch of ``total`` threads runs inline on
        ``threads`` threads, handing a launch over costing ``dispatch`` seconds.

        Inline when its expected time is at most what splitting saves,
        ``t <= overhead * n / (n - 1)`` with ``overhead`` the larger of ``dispatch`` and
        ``pool_overhead``, with hysteresis: a kernel on the pool returns inline only
        below ``1 / hysteresis`` of that line, one inline goes to the pool only above
        ``hysteresis`` times it, so costs measured near the line do not flip the choice
        launch by launch. Kept inline by ``pool_overhead`` alone, it tries the pool every
        ``retry_pool_every``-th launch (a slow pool launch is often the host's doing)."""
        per, over = self._spt, self._over
        assert per is not None, "runs_inline needs a measured kernel"
        t, scale = per * total, threads / (threads - 1)
        line = dispatch * scale
        if over is not None:
            line = max(line, over * scale)
        inline = t < line / hysteresis if self.on_pool else t <= line * hysteresis
        if inline and t > dispatch * scale * hysteresis:  # held inline by the overhead alone
            self.held_inline += 1
            if self.held_inline >= retry_pool_every:
                inline, self.held_inline = False, 0
        elif not inline:
            self.held_inline = 0
        self.on_pool = not inline
        return inline


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
    per = cost._spt if measured else None  # cost.seconds_per_thread, without the property
    if per is None:  # not measured: small or first launches run inline (and are measured)
        inline = total < min_parallel or (measured and total <= measure_inline_up_to)
    else:
        inline = cost.runs_inline(total, n, dispatch_seconds())
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
