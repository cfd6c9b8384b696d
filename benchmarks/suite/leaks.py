"""The leak rows (issue 17 item 7): memory stays flat over long runs of the hot paths.

Three phases, each on one device, each measured after a warm-up of a tenth of its
count (so caches, pools and the plan of each kernel exist before the first reading):

- ``launches``: 10^5 plain launches of a small kernel on the same arrays;
- ``captures``: 10^4 graph captures of two launches (``kdsl.ScopedCapture``), each
  replayed once (``capture_launch``) and dropped;
- ``allocations``: 10^4 cycles of allocating a 256 KiB array, writing it with a
  kernel and dropping it.

Per phase the cell's value is the growth of the process's resident memory (RSS) in
percent of its size before the phase (target: within 1%); ``extra`` holds the RSS
before and after, the growth in Python objects the collector tracks, and on CUDA the
bytes held by live arrays (``get_mempool_used_mem_current``) and by CuPy's pool
before and after.
"""

from __future__ import annotations

import gc
import os
import time
from collections.abc import Callable
from typing import Any

import numpy as np

import kdsl as wp
from suite.harness import Cell, Stats, short_error

#: Iterations per phase (``quick``: a tenth).
COUNTS = {"launches": 100_000, "captures": 10_000, "allocations": 10_000}
#: The target: resident memory after a phase within this fraction of before.
FLAT = 0.01
ALLOC_FLOATS = 65_536  # 256 KiB: large enough that a leaked buffer shows in the RSS


@wp.kernel
def bump_kernel(a: wp.array(dtype=float), b: wp.array(dtype=float)):
    i = wp.tid()
    b[i] = a[i] + 1.0


def rss_bytes() -> int:
    """This process's resident memory (Linux ``/proc/self/statm``; else peak RSS)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError):
        import resource

        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def _pool(device: str) -> dict[str, int]:
    """Bytes held by live kdsl arrays and by CuPy's pool on a CUDA device (empty on cpu)."""
    dev = wp.get_device(device)
    if not dev.is_cuda:
        return {}
    import cupy

    return {
        "used": wp.get_mempool_used_mem_current(dev),
        "pool": cupy.get_default_memory_pool().total_bytes(),
    }


def _reading(device: str) -> dict[str, Any]:
    wp.synchronize_device(device)
    gc.collect()
    return {"rss": rss_bytes(), "objects": len(gc.get_objects()), **_pool(device)}


def _phases(device: str) -> dict[str, Callable[[int], None]]:
    n = 1024
    a = wp.array(np.ones(n, np.float32), device=device)
    b = wp.zeros(n, dtype=float, device=device)

    def launches(count: int) -> None:
        for _ in range(count):
            wp.launch(bump_kernel, dim=n, inputs=[a, b], device=device)

    def captures(count: int) -> None:
        for _ in range(count):
            with wp.ScopedCapture(device=device) as capture:
                wp.launch(bump_kernel, dim=n, inputs=[a, b], device=device)
                wp.launch(bump_kernel, dim=n, inputs=[b, a], device=device)
            wp.capture_launch(capture.graph)

    def allocations(count: int) -> None:
        for _ in range(count):
            tmp = wp.zeros(ALLOC_FLOATS, dtype=float, device=device)
            wp.launch(bump_kernel, dim=n, inputs=[a, tmp], device=device)
            del tmp

    return {"launches": launches, "captures": captures, "allocations": allocations}


def run_leaks(device: str, quick: bool) -> dict[str, Cell]:
    """One cell per phase: RSS growth in percent (the median), readings in ``extra``."""
    cells: dict[str, Cell] = {}
    try:
        phases = _phases(device)
    except Exception as e:
        return {f"leak_{k}": Cell(status=short_error(e)) for k in COUNTS}
    for name, body in phases.items():
        count = COUNTS[name] // (10 if quick else 1)
        try:
            body(max(1, count // 10))  # warm-up: plans, caches, pools
            before = _reading(device)
            t0 = time.perf_counter()
            body(count)
            seconds = time.perf_counter() - t0
            after = _reading(device)
        except Exception as e:
            cells[f"leak_{name}"] = Cell(status=short_error(e))
            continue
        growth = 100.0 * (after["rss"] - before["rss"]) / before["rss"]
        extra = {"count": count, "seconds": seconds, "before": before, "after": after,
                 "objects": after["objects"] - before["objects"]}  # fmt: skip
        cells[f"leak_{name}"] = Cell(Stats(growth, growth, 0.0), extra=extra)
    return cells


def leak_row(name: str, cell: Cell | None) -> tuple[str, str, str, str]:
    """(title, kdsl cell text, target text, a line of details) of one leak row."""
    what = {"launches": "10^5 launches", "captures": "10^4 captures+replays",
            "allocations": "10^4 alloc/free"}[name]  # fmt: skip
    title = f"leak: {what} [RSS %]"
    if cell is None or cell.stats is None:
        return title, "-" if cell is None else cell.status, "-", ""
    e = cell.extra
    before, after = e["before"], e["after"]
    growth = cell.stats.median
    detail = (f"{what} ({e['count']} run, {e['seconds']:.1f} s): RSS "
              f"{before['rss'] / 2**20:.1f} -> {after['rss'] / 2**20:.1f} MiB, "
              f"{e['objects']:+d} tracked Python objects")  # fmt: skip
    ok = abs(growth) <= 100 * FLAT
    if "used" in after:
        detail += (f", CuPy pool {before['pool'] / 2**20:.1f} -> {after['pool'] / 2**20:.1f} "
                   f"MiB, live arrays {after['used'] - before['used']:+d} B")  # fmt: skip
        ok = ok and after["pool"] <= before["pool"] * (1 + FLAT)
    return title, f"{growth:+.2f}", ("yes" if ok else "no") + " (flat, <=1%)", detail


def print_details(cells: dict[str, dict[str, Cell]]) -> None:
    """The leak rows' readings, one line each, under the table."""
    for name in COUNTS:
        detail = leak_row(name, cells.get(f"leak_{name}", {}).get("kdsl"))[3]
        if detail:
            print(f"  {detail}")
