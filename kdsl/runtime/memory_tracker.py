"""Allocation tracking: Warp's ``ScopedMemoryTracker`` and ``print_memory_report``.

While a tracker is active, every buffer kdsl allocates (``cuda_memory.empty``: array
constructors, copies to a device, gradients; cpu and cuda alike) is recorded with its
size, device, the user's call site (the first frame outside kdsl) and the scope path of
the nested trackers; its free is recorded when the buffer dies. Arrays that wrap
memory kdsl did not allocate (NumPy data adopted without a copy, ``from_ptr``, DLPack)
are not kdsl allocations and are not counted. Warp tracks its native allocations the
same way; kdsl has no native allocations besides these.
"""

from __future__ import annotations

import io
import itertools
import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TextIO

from kdsl.errors import KdslError, KdslValueError, is_internal_frame

_lock = threading.Lock()
_active = 0
_scopes = threading.local()
_seq = itertools.count()


@dataclass
class Allocation:
    """One tracked allocation."""

    seq: int
    nbytes: int
    device: str
    scope: str
    site: str


#: Live allocations by sequence number.
LIVE: dict[int, Allocation] = {}
#: Per scope path: [allocated bytes, freed bytes, allocation count, peak live bytes].
TOTALS: dict[str, list[int]] = {}


def active() -> bool:
    """True while a tracker is active (checked on every allocation: one global read)."""
    return _active > 0


def _scope_path() -> str:
    stack = getattr(_scopes, "stack", None)
    return "/".join(stack) if stack else "root"


def _call_site() -> str:
    frame = sys._getframe(2)
    while frame is not None and is_internal_frame(frame.f_code.co_filename):
        frame = frame.f_back
    if frame is None:
        return "(kdsl)"
    return f"{frame.f_code.co_filename}:{frame.f_lineno} : {frame.f_code.co_name}()"


def _live_bytes(scope: str) -> int:
    return sum(a.nbytes for a in LIVE.values() if a.scope == scope)


def note_alloc(nbytes: int, device: Any) -> int:
    """Record an allocation; returns the token ``note_free`` takes."""
    a = Allocation(next(_seq), int(nbytes), str(device), _scope_path(), _call_site())
    with _lock:
        LIVE[a.seq] = a
        t = TOTALS.setdefault(a.scope, [0, 0, 0, 0])
        t[0] += a.nbytes
        t[2] += 1
        t[3] = max(t[3], _live_bytes(a.scope))
    return a.seq


def note_free(token: int) -> None:
    """Record that the allocation ``token`` was freed (from a finalizer: never raises)."""
    with _lock:
        a = LIVE.pop(token, None)
        if a is not None and a.scope in TOTALS:
            TOTALS[a.scope][1] += a.nbytes


def _human(n: int) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if abs(n) < 1024 or unit == "GiB":
            return f"{n} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024  # type: ignore[assignment]
    return f"{n} B"


def report(scope_prefix: str | None = None, sort: str = "size", max_items: int = 10) -> str:
    """The report text: totals per scope, then the live allocations (largest first)."""
    if sort not in ("size", "chronological"):
        raise KdslValueError(f"invalid sort order {sort!r}; expected 'size' or 'chronological'")
    if not isinstance(max_items, int) or max_items < 0:
        raise KdslValueError(f"max_items must be a non-negative int, not {max_items!r}")
    with _lock:
        scopes = {k: list(v) for k, v in TOTALS.items()
                  if scope_prefix is None or k == scope_prefix
                  or k.startswith(scope_prefix + "/")}  # fmt: skip
        live = [a for a in LIVE.values() if a.scope in scopes]
    out = io.StringIO()
    out.write("kdsl memory report\n")
    for name, (alloc, freed, count, peak) in sorted(scopes.items()):
        out.write(f"  scope {name}: {count} allocations, {_human(alloc)} allocated, "
                  f"{_human(freed)} freed, {_human(alloc - freed)} live, peak {_human(peak)}\n")  # fmt: skip
    by_device: dict[str, int] = {}
    for a in live:
        by_device[a.device] = by_device.get(a.device, 0) + a.nbytes
    for dev, n in sorted(by_device.items()):
        out.write(f"  live on {dev}: {_human(n)}\n")
    key: Callable[[Allocation], Any] = (lambda a: -a.nbytes) if sort == "size" else (
        lambda a: a.seq)  # fmt: skip
    shown = sorted(live, key=key)[:max_items]
    if shown:
        out.write(f"  live allocations ({len(live)}, showing {len(shown)}):\n")
    for a in shown:
        out.write(f"    {_human(a.nbytes):>10}  {a.device:<8} {a.scope}  {a.site}\n")
    return out.getvalue()


class ScopedMemoryTracker:
    """``with ScopedMemoryTracker("name"):`` tracks kdsl's allocations inside the block.

    Nested trackers form a scope path ("sim/collision"). On exit a summary of the
    scope is printed (``print=True``) or passed to ``report_func``. ``active=False``
    makes it a no-op, so it can stay in code.
    """

    def __init__(
        self,
        name: str = "root",
        active: bool = True,
        print: bool = True,  # Warp's parameter name
        report_func: Callable[[str], None] | None = None,
    ) -> None:
        if not isinstance(name, str) or not name or "/" in name:
            raise KdslValueError(f"ScopedMemoryTracker: name must be a non-empty str without "
                                 f"'/', not {name!r}")  # fmt: skip
        self.name = name
        self.active = active
        self.print = print
        self.report_func = report_func
        self.path = ""

    def __enter__(self) -> ScopedMemoryTracker:
        global _active
        if not self.active:
            return self
        stack = getattr(_scopes, "stack", None)
        if stack is None:
            stack = _scopes.stack = []
        stack.append(self.name)
        self.path = "/".join(stack)
        with _lock:
            _active += 1
        return self

    def __exit__(self, *exc_info: object) -> None:
        global _active
        if not self.active:
            return
        _scopes.stack.pop()
        with _lock:
            _active -= 1
        text = report(self.path)
        if self.report_func is not None:
            self.report_func(text)
        elif self.print:
            sys.stdout.write(text)


def print_memory_report(file: TextIO | None = None, sort: str = "size",
                        max_items: int = 10) -> None:  # fmt: skip
    """Print every tracked allocation still live and the totals per scope.

    Needs an active ``ScopedMemoryTracker`` (kdsl tracks nothing otherwise).
    """
    if not active():
        raise KdslError("allocation tracking is not active: print_memory_report works inside "
                        "a kdsl.ScopedMemoryTracker block")  # fmt: skip
    (file or sys.stdout).write(report(None, sort, max_items))
