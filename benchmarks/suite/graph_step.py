"""The graph rows: a 100-kernel simulation step replayed as one graph against 100 launches.

The step is 50 rounds of a 3-point smoothing stencil and an update (kdsl only; the
same code Warp users capture with ``wp.ScopedCapture``). Both forms run on copies of
one state and must agree bit for bit before either is timed.
"""

from __future__ import annotations

from typing import Any

import numpy as np

import kdsl as wp
from suite import harness
from suite.harness import Cell, Stats

KERNELS_PER_STEP = 100


@wp.kernel
def smooth_kernel(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    n = x.shape[0]
    y[i] = 0.25 * x[wp.max(i - 1, 0)] + 0.5 * x[i] + 0.25 * x[wp.min(i + 1, n - 1)]


@wp.kernel
def update_kernel(x: wp.array(dtype=float), y: wp.array(dtype=float), s: float):
    i = wp.tid()
    x[i] = x[i] + s * (y[i] - x[i])


def _state(n: int, device: str) -> tuple[Any, Any]:
    x = np.random.default_rng(3).random(n, dtype=np.float32)
    return wp.array(x, device=device), wp.zeros(n, dtype=float, device=device)


def _step(x: Any, y: Any, n: int, device: str) -> None:
    for _ in range(KERNELS_PER_STEP // 2):
        wp.launch(smooth_kernel, dim=n, inputs=[x, y], device=device)
        wp.launch(update_kernel, dim=n, inputs=[x, y, 0.5], device=device)


def run_graph(device: str, quick: bool, reps: int | None) -> Cell:
    """The graph replay's speedup over plain launches (the median), both timings in extra."""
    n = 1024 if quick else 4096
    try:
        x1, y1 = _state(n, device)
        x2, y2 = _state(n, device)
        with wp.ScopedCapture(device=device) as capture:
            _step(x2, y2, n, device)
        graph = capture.graph
        for _ in range(2):
            _step(x1, y1, n, device)
            wp.capture_launch(graph)
        if not np.array_equal(x1.numpy(), x2.numpy()):
            return Cell(status="wrong: the graph's result differs from plain launches")

        def plain() -> None:
            _step(x1, y1, n, device)

        def replay() -> None:
            wp.capture_launch(graph)

        if device == "cpu":
            t_plain = harness.measure(plain, reps or 10).median
            t_graph = harness.measure(replay, reps or 10).median
        else:
            sync = wp.synchronize_device
            t_plain = harness.measure_device(plain, lambda: sync(device), reps or 10)[0].median
            t_graph = harness.measure_device(replay, lambda: sync(device), reps or 10)[0].median
    except Exception as e:
        return Cell(status=harness.short_error(e))
    speedup = t_plain / t_graph
    return Cell(Stats(speedup, speedup, 0.0),
                extra={"plain_s": t_plain, "graph_s": t_graph, "n": n,
                       "kernels": KERNELS_PER_STEP})  # fmt: skip


def graph_title(cell: Cell | None) -> str:
    """The row title with both timings (ms per 100-kernel step) when measured."""
    if cell is None or cell.status != "ok":
        return "graph: 100-kernel step replay vs launches"
    e = cell.extra
    return (f"graph: 100-kernel step, {e['plain_s'] * 1e3:.2f} ms launched -> "
            f"{e['graph_s'] * 1e3:.2f} ms replayed")  # fmt: skip
