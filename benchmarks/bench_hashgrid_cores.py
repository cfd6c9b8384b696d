"""The hash-grid workload per core: every side on one thread, timed in CPU time.

    python benchmarks/bench_hashgrid_cores.py [--points N] [--reps R] [--rounds K]

The ``hash_grid`` section of ``bench_geometry.py`` times each side's own threads in wall
time, which on a host shared with other jobs mostly measures how each runtime splits
its work around them. Here kdsl, Warp, Numba and Taichi (those installed) each run on
one thread, and each build and query is timed in this process's CPU time
(``time.process_time``), which the other jobs on the host do not inflate. The sides
take turns, ``--rounds`` times, ``--reps`` timed calls each; the table gives each
side's median and each peer's time over kdsl's as the median of the per-round ratios.
Workload, kernels and answer checks: ``bench_geometry_hashgrid``.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from bench_geometry_hashgrid import (
    check_counts,
    check_sums,
    hash_grid_kernels,
    radius_for,
    workload,
)

import kdsl as wp
from kdsl.backends.cpu import pool


def cpu_seconds(fn, reps: int) -> float:
    """The median CPU seconds of ``reps`` calls of ``fn`` after one untimed call."""
    fn()
    times = []
    for _ in range(reps):
        t = time.process_time()
        fn()
        times.append(time.process_time() - t)
    return statistics.median(times)


def grid_side(m, pts: np.ndarray, radius: float, dim: int):
    """kdsl's or Warp's ``(build, query, sums, counts)`` on the CPU (one thread)."""
    sum_kernel, count_kernel = hash_grid_kernels(m)
    n = len(pts)
    points = m.array(pts, dtype=m.vec3, device="cpu")
    out = m.zeros(n, dtype=m.vec3, device="cpu")
    grid = m.HashGrid(dim, dim, dim, device="cpu")
    grid.build(points, radius)
    counts = m.zeros(n, dtype=int, device="cpu")
    m.launch(count_kernel, dim=n, inputs=[grid.id, points, radius, counts], device="cpu")

    def query():
        m.launch(sum_kernel, dim=n, inputs=[grid.id, points, out, radius], device="cpu")

    return (lambda: grid.build(points, radius)), query, out.numpy, counts.numpy


def sides(pts: np.ndarray, radius: float, dim: int) -> dict:
    """Each installed side's ``(build, query, sums)``, kdsl first."""
    pool.set_num_threads(1)
    build, query, sums, counts = grid_side(wp, pts, radius, dim)
    out = {"kdsl": (build, query, sums)}
    problems = check_counts(counts(), pts, radius)
    if importlib.util.find_spec("warp") is not None:
        import warp

        warp.config.quiet = True
        warp.init()
        out["warp"] = grid_side(warp, pts, radius, dim)[:3]
    if importlib.util.find_spec("numba") is not None:
        import numba
        from suite import hashgrid_numba as nb

        numba.set_num_threads(1)
        n, cells = len(pts), dim**3
        keys, order = np.empty(n, np.int64), np.empty(n, np.int64)
        starts, ends = np.zeros(cells, np.int64), np.zeros(cells, np.int64)
        res, r = np.zeros((n, 3), np.float32), np.float32(radius)
        out["numba"] = (lambda: nb.build(pts, r, dim, keys, starts, ends, order),
                        lambda: nb.neighbour_sum(pts, r, dim, starts, ends, order, res),
                        lambda: res)  # fmt: skip
    if importlib.util.find_spec("taichi") is not None:
        from suite import hashgrid_taichi as ti_side

        out["taichi"] = ti_side.prepare(pts, radius, dim, threads=1)
    for name, (build, query, sums) in out.items():
        build()
        query()
        if name != "kdsl":
            problems += check_sums(out["kdsl"][2](), sums(), counts(), name)
    if problems:
        sys.exit("\n".join(problems))
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--points", type=int, default=200_000)
    p.add_argument("--neighbours", type=float, default=30.0)
    p.add_argument("--grid-dim", type=int, default=128)
    p.add_argument("--reps", type=int, default=3)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--json", type=Path, default=None)
    a = p.parse_args()
    pts, radius = workload(a.points), radius_for(a.points, a.neighbours)
    runners = sides(pts, radius, a.grid_dim)
    rounds = []
    for _ in range(a.rounds):
        rounds.append({name: {"build_s": cpu_seconds(b, a.reps), "query_s": cpu_seconds(q, a.reps)}
                       for name, (b, q, _) in runners.items()})  # fmt: skip
    print(f"{a.points:,} points, radius {radius:.4f}, {a.grid_dim}^3 grid; one thread each, "
          f"CPU ms (median of {a.rounds} rounds of {a.reps})")  # fmt: skip
    print(f"{'side':<8}{'build':>9}{'query':>9}{'peer/kdsl build':>17}{'peer/kdsl query':>17}")
    table = {}
    for name in runners:
        row = {k: statistics.median(r[name][k] for r in rounds) for k in ("build_s", "query_s")}
        for k in ("build_s", "query_s"):
            row[k + "_ratio"] = statistics.median(r[name][k] / r["kdsl"][k] for r in rounds)
        table[name] = row
        ratios = "" if name == "kdsl" else (f"{row['build_s_ratio']:16.2f}x"
                                             f"{row['query_s_ratio']:16.2f}x")  # fmt: skip
        print(f"{name:<8}{1e3 * row['build_s']:9.2f}{1e3 * row['query_s']:9.1f}{ratios}")
    if a.json is not None:
        a.json.write_text(json.dumps({"rounds": rounds, "table": table}, indent=1))


if __name__ == "__main__":
    main()
