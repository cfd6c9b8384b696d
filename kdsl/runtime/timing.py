"""Timing: ``ScopedTimer`` and per-kernel launch records (``timing_begin``/``timing_end``).

Between ``timing_begin()`` and ``timing_end()`` every kernel launch is recorded with
its name, device and elapsed milliseconds: on the CPU the wall time of the launch
(CPU launches return when the kernel is done), on CUDA the time between two timing
events recorded on the launch's stream around it. When timing is off a launch
pays one ``is None`` test. kdsl records kernel launches only: the filters for
copies, memsets and graphs (``TIMING_MEMCPY``, ...) are accepted and select nothing
else (docs/runtime.md).
"""

from __future__ import annotations

import cProfile
import threading
import time
from collections.abc import Callable
from typing import Any

from kdsl.errors import KdslError
from kdsl.runtime import logger as _log
from kdsl.runtime.stream import Event, get_event_elapsed_time, synchronize

TIMING_KERNEL = 1
TIMING_KERNEL_BUILTIN = 2
TIMING_MEMCPY = 4
TIMING_MEMSET = 8
TIMING_GRAPH = 16
TIMING_ALL = 0xFFFFFFFF


class TimingResult:
    """One recorded activity: ``device``, ``name``, ``filter`` (``TIMING_KERNEL``) and
    ``elapsed`` (milliseconds)."""

    def __init__(self, device: Any, name: str, filter: int, elapsed: float) -> None:
        self.device = device
        self.name = name
        self.filter = filter
        self.elapsed = elapsed

    def __repr__(self) -> str:
        return f"TimingResult({self.device.alias!r}, {self.name!r}, {self.elapsed:.6f} ms)"


#: The launches recorded since ``timing_begin`` (None while timing is off). Each entry is
#: (device, name, elapsed ms) or, for CUDA, (device, name, (start event, end event)).
RECORDING: list[tuple[Any, str, Any]] | None = None


def timed_launch(backend: Any, compiled: Any, dims: Any, args: Any, stream: Any,
                 device: Any, name: str) -> None:  # fmt: skip
    """Run one launch and record how long it took (the hook ``launch`` calls while on)."""
    rec = RECORDING
    if device.is_cpu:
        t0 = time.perf_counter_ns()
        backend.launch(compiled, dims, args, stream)
        elapsed: Any = (time.perf_counter_ns() - t0) / 1e6
    else:
        start = Event(device, enable_timing=True)
        end = Event(device, enable_timing=True)
        stream.record_event(start)
        backend.launch(compiled, dims, args, stream)
        stream.record_event(end)
        elapsed = (start, end)
    if rec is not None:
        rec.append((device, name, elapsed))


def timing_begin(cuda_filter: int = TIMING_ALL, synchronize: bool = True) -> None:
    """Start recording kernel launches (a running recording starts over).

    ``cuda_filter`` picks activities (``TIMING_KERNEL``, ``TIMING_ALL``, ...); kdsl
    records kernel launches, so a filter without ``TIMING_KERNEL`` records nothing.
    ``synchronize`` waits for earlier work first, so it is not counted.
    """
    global RECORDING, _filter
    if not isinstance(cuda_filter, int) or isinstance(cuda_filter, bool) or cuda_filter < 0:
        raise KdslError(f"timing_begin: cuda_filter must be TIMING_* flags (an int), not "
                        f"{cuda_filter!r}")  # fmt: skip
    if synchronize:
        _sync()
    _filter = cuda_filter
    RECORDING = [] if cuda_filter & TIMING_KERNEL else None


_filter = 0


def _sync() -> None:
    synchronize()


def timing_end(synchronize: bool = True) -> list[TimingResult]:
    """Stop recording; the launches recorded since ``timing_begin``, in launch order.

    Names follow Warp: ``forward kernel NAME`` (``backward kernel NAME`` for adjoint
    launches). CUDA times are read from the events once the work is done.
    """
    global RECORDING, _filter
    rec, RECORDING, _filter = RECORDING, None, 0
    if synchronize:
        _sync()
    out = []
    for device, name, elapsed in rec or ():
        if isinstance(elapsed, tuple):
            elapsed = get_event_elapsed_time(*elapsed, synchronize=True)
        out.append(TimingResult(device, name, TIMING_KERNEL, float(elapsed)))
    return out


def timing_print(results: list[TimingResult], indent: str = "") -> None:
    """Print a timeline of ``results``, then totals per activity and per device (Warp's
    layout)."""
    if not results:
        print("No activity")
        return
    width = max(len("Activity"), *(len(r.name) for r in results)) + 1
    rule = f"{indent}----------------+---------+{'-' * width}"
    per_name: dict[str, list] = {}
    per_dev: dict[str, list] = {}
    print(f"{indent}Timeline:")
    print(rule)
    print(f"{indent}Time            | Device  | Activity")
    print(rule)
    for r in results:
        alias = r.device.alias
        for table, key in ((per_name, r.name), (per_dev, alias)):
            agg = table.setdefault(key, [0, 0.0])
            agg[0] += 1
            agg[1] += r.elapsed
        print(f"{indent}{r.elapsed:12.6f} ms | {alias:7s} | {r.name}")
    for title, column, table in (("Activity summary", "Activity", per_name),
                                 ("Device summary", "Device", per_dev)):  # fmt: skip
        print()
        print(f"{indent}{title}:")
        print(rule)
        print(f"{indent}Total time      | Count   | {column}")
        print(rule)
        for key, (count, total) in table.items():
            print(f"{indent}{total:12.6f} ms | {count:7d} | {key}")


class ScopedTimer:
    """``with ScopedTimer("step"):`` measures a block; ``elapsed`` holds milliseconds.

    ``print``: log ``name took X ms`` on exit (nested timers indent by four spaces);
    ``dict``: append the time to ``dict[name]``; ``synchronize``: wait for the device
    work before and after, so GPU time is counted; ``cuda_filter``: record the kernel
    launches inside (``timing_begin``) and report them with ``report_func``
    (``timing_print`` by default); ``detailed``: profile the block with cProfile;
    ``active=False``: do nothing. ``use_nvtx``/``color`` are accepted and ignored.
    """

    _local = threading.local()
    enabled = True

    def __init__(
        self,
        name: str,
        active: bool = True,
        print: bool = True,
        detailed: bool = False,
        dict: dict[str, list[float]] | None = None,
        use_nvtx: bool = False,
        color: int | str = "rapids",
        synchronize: bool = False,
        cuda_filter: int = 0,
        report_func: Callable[..., None] | None = None,
        skip_tape: bool = False,
    ) -> None:
        self.name = name
        self.active = active and self.enabled
        self.print = print
        self.detailed = detailed
        self.dict = dict
        self.use_nvtx = use_nvtx
        self.color = color
        self.synchronize = synchronize
        self.cuda_filter = cuda_filter
        self.report_func = report_func or timing_print
        self.skip_tape = skip_tape
        self.elapsed = 0.0
        self.extra_msg = ""
        self.timing_results: list[TimingResult] = []
        if dict is not None and name not in dict:
            dict[name] = []
        if not hasattr(ScopedTimer._local, "indent"):
            ScopedTimer._local.indent = -1

    def __enter__(self) -> ScopedTimer:
        if self.active:
            if self.synchronize:
                _sync()
            if self.cuda_filter:
                timing_begin(self.cuda_filter, synchronize=not self.synchronize)
            if self.detailed:
                self._profile = cProfile.Profile()
                self._profile.enable()
            if self.print:
                ScopedTimer._local.indent += 1
                _log.log_debug(f"{'    ' * ScopedTimer._local.indent}{self.name} ...")
            self._start = time.perf_counter_ns()
        if not self.skip_tape:
            from kdsl.runtime import tape

            if tape.ACTIVE:
                tape.ACTIVE[-1].record_scope_begin(self.name)
        return self

    def __exit__(self, exc_type: Any, *exc_info: object) -> None:
        if not self.skip_tape:
            from kdsl.runtime import tape

            if tape.ACTIVE:
                tape.ACTIVE[-1].record_scope_end()
        if not self.active:
            return
        error = None
        if self.synchronize:
            try:
                _sync()
            except Exception as e:  # report after the timer has finished
                error = e
        self.elapsed = (time.perf_counter_ns() - self._start) / 1e6
        if self.detailed:
            self._profile.disable()
            self._profile.print_stats(sort="tottime")
        if self.cuda_filter:
            self.timing_results = timing_end(synchronize=not self.synchronize)
        if self.dict is not None:
            self.dict[self.name].append(self.elapsed)
        if self.print:
            indent = "    " * ScopedTimer._local.indent
            if self.timing_results:
                self.report_func(self.timing_results, indent=indent)
            extra = f" {self.extra_msg}" if self.extra_msg else ""
            _log.get_logger().info(f"{indent}{self.name} took {self.elapsed:.2f} ms{extra}")
            ScopedTimer._local.indent -= 1
        if error is not None and exc_type is None:
            raise error
