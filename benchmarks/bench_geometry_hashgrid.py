"""Hash grids, kdsl beside Warp (and Numba, Taichi): the ``hash_grid`` section of the
geometry benchmark (``bench_geometry.py --section hash_grid``).

Workload (issue 16): ``--points`` particles uniform in the unit box (seed 0) and the
radius ``r`` at which a point has ``--neighbours`` others within ``r`` on average
(``n * 4/3 pi r^3 = neighbours``: 0.0330 for 200k and 30), bucketed with cell width
``r`` into a ``--grid-dim``^3 wrapped grid (Warp's examples use 128^3). Timed:

- ``build``: ``grid.build(points, r)`` of an existing grid (Warp's pattern: a rebuild
  every step, the buffers reused);
- ``query``: the seed's ``sum`` kernel (each point sums its neighbours' positions over
  ``hash_grid_query`` / ``hash_grid_query_next``) over every point.

kdsl and Warp run the same kernel source (``hash_grid_kernels(m)`` with ``m`` either
module) on ``--device``; Warp's CPU kernels use one core, kdsl's every core the
process may run on (pin with ``taskset -c 0`` to compare per core). On the CPU, when
installed (the ``bench`` extra), Numba (``@njit(parallel=True)``) and Taichi (its CPU
backend) build the same wrapped grid with a counting sort and run the same 27-cell
query. Times are medians of ``--reps`` runs after a warm-up (compiles excluded).

Before any time is printed, each point's neighbour count from kdsl must equal a
float64 brute force on a subsample of points (pairs within rounding of ``r`` aside),
and every side's sums must equal kdsl's within float32 rounding; otherwise the run
exits 1 with the reason.
"""

from __future__ import annotations

import importlib
import importlib.util
import math
import sys

import numpy as np
from suite.harness import median_seconds

import kdsl as wp

#: Points checked against the brute force (a seeded subsample).
CHECK_POINTS = 512
#: Sums agree when within this of each other, relative to the sum of the neighbours'
#: position magnitudes (float32 sums in another order).
SUM_RTOL = 1.0e-5


def radius_for(points: int, neighbours: float) -> float:
    """The radius at which ``points`` uniform points in the unit box have ``neighbours``
    points within it on average (``points * 4/3 pi r^3 = neighbours``)."""
    return (3.0 * neighbours / (4.0 * math.pi * points)) ** (1.0 / 3.0)


def workload(points: int, seed: int = 0) -> np.ndarray:
    """``points`` float32 points uniform in the unit box, (points, 3)."""
    return np.random.default_rng(seed).random((points, 3)).astype(np.float32)


def hash_grid_kernels(m):
    """The seed's ``sum`` kernel and a neighbour counter in module ``m``'s API (kdsl or
    warp): one source, both compilers."""

    @m.kernel
    def sum(grid: m.uint64, points: m.array(dtype=m.vec3), output: m.array(dtype=m.vec3),  # noqa: A001
            radius: float):  # fmt: skip
        tid = m.tid()
        p = points[tid]
        query = m.hash_grid_query(grid, p, radius)
        index = int(0)  # noqa: UP018, RUF046 - the seed's spelling
        sum = m.vec3()  # noqa: A001 - the seed's name
        while m.hash_grid_query_next(query, index):
            neighbor = points[index]
            dist = m.length(p - neighbor)
            if dist < radius:
                sum += neighbor  # noqa: A001
        output[tid] = sum

    @m.kernel
    def count(grid: m.uint64, points: m.array(dtype=m.vec3), radius: float,
              output: m.array(dtype=int)):  # fmt: skip
        tid = m.tid()
        p = points[tid]
        query = m.hash_grid_query(grid, p, radius)
        index = int(0)  # noqa: UP018, RUF046
        n = int(0)  # noqa: UP018, RUF046
        while m.hash_grid_query_next(query, index):
            if m.length(p - points[index]) < radius:
                n += 1
        output[tid] = n

    return sum, count


def _run_side(m, name: str, pts: np.ndarray, radius: float, dim: int, device: str,
              reps: int, sync) -> tuple[dict, dict]:  # fmt: skip
    """Time module ``m``'s grid rebuild and the seed's query; the row and its answers."""
    sum_kernel, count_kernel = hash_grid_kernels(m)
    n = len(pts)
    points = m.array(pts, dtype=m.vec3, device=device)
    out = m.zeros(n, dtype=m.vec3, device=device)
    counts = m.zeros(n, dtype=int, device=device)
    grid = m.HashGrid(dim, dim, dim, device=device)
    grid.build(points, radius)
    row = {"section": "hash_grid", "side": name, "device": device, "points": n,
           "radius": radius, "grid_dim": dim}  # fmt: skip
    row["build_s"] = median_seconds(lambda: grid.build(points, radius), reps, sync)
    row["query_s"] = median_seconds(
        lambda: m.launch(sum_kernel, dim=n, inputs=[grid.id, points, out, radius], device=device),
        reps, sync,
    )  # fmt: skip
    m.launch(count_kernel, dim=n, inputs=[grid.id, points, radius, counts], device=device)
    sync()
    return row, {"sum": out.numpy().copy(), "count": counts.numpy().copy()}


def brute_counts(pts: np.ndarray, idx: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """For points ``idx``: how many points lie within ``radius`` (float64, itself
    included, as the seed's loop counts it) and how many lie within rounding of it."""
    p64 = pts.astype(np.float64)
    counts, unsure = np.zeros(len(idx), np.int64), np.zeros(len(idx), np.int64)
    for s in range(0, len(idx), 32):
        d = np.linalg.norm(p64[None, :, :] - p64[idx[s:s + 32], None, :], axis=2)
        counts[s:s + 32] = (d < radius).sum(axis=1)
        unsure[s:s + 32] = (np.abs(d - radius) < 1e-5 * radius).sum(axis=1)
    return counts, unsure


def check_counts(counts: np.ndarray, pts: np.ndarray, radius: float, seed: int = 1) -> list[str]:
    """Where kdsl's neighbour counts differ from the brute force on a subsample."""
    idx = np.random.default_rng(seed).choice(len(pts), min(CHECK_POINTS, len(pts)), replace=False)
    ref, unsure = brute_counts(pts, idx, radius)
    bad = np.abs(counts[idx] - ref) > unsure
    if bad.any():
        i = int(idx[np.argmax(bad)])
        return [f"kdsl neighbour counts differ from the brute force at {int(bad.sum())} of "
                f"{len(idx)} points (point {i}: {int(counts[i])}, brute force "
                f"{int(ref[np.argmax(bad)])})"]  # fmt: skip
    return []


def check_sums(ours: np.ndarray, theirs: np.ndarray, counts: np.ndarray, peer: str) -> list[str]:
    """Where a peer's neighbour sums differ from kdsl's beyond float32 rounding (each
    coordinate of a sum of ``counts`` points in the unit box is at most ``counts``)."""
    err = np.abs(ours.astype(np.float64) - theirs) / np.maximum(counts, 1)[:, None]
    if not np.isfinite(theirs).all() or err.max(initial=0.0) > SUM_RTOL:
        return [f"kdsl vs {peer}: neighbour sums differ by up to {err.max():.2e} (relative)"]
    return []


def _peer_sides(pts: np.ndarray, radius: float, dim: int, reps: int,
                ours: dict) -> tuple[list[dict], list[str]]:  # fmt: skip
    """Numba's and Taichi's rows (for those installed) and where their sums differ."""
    rows, problems = [], []
    for package, module in (("numba", "suite.hashgrid_numba"), ("taichi", "suite.hashgrid_taichi")):
        if importlib.util.find_spec(package) is None:
            continue  # not installed: the bench extra brings it
        impl = importlib.import_module(module)
        times, sums = impl.run(pts, radius, dim, reps)
        rows.append({"section": "hash_grid", "side": impl.NAME, "device": "cpu",
                     "points": len(pts), "radius": radius, "grid_dim": dim, **times})  # fmt: skip
        problems += check_sums(ours["sum"], sums, ours["count"], impl.NAME)
    return rows, problems


def _warp_side(pts: np.ndarray, radius: float, dim: int, dev: str, reps: int,
               ours: dict) -> tuple[list[dict], list[str]]:  # fmt: skip
    """Warp's row (none where warp-lang is missing) and where its answers differ."""
    if importlib.util.find_spec("warp") is None:
        return [], []
    import warp

    warp.config.quiet = True
    warp.init()
    wrow, theirs = _run_side(warp, "warp", pts, radius, dim, dev, reps, warp.synchronize)
    problems = check_sums(ours["sum"], theirs["sum"], ours["count"], "Warp")
    differ = int((theirs["count"] != ours["count"]).sum())
    if differ:
        problems.insert(0, f"kdsl vs Warp: neighbour counts differ at {differ} points")
    return [wrow], problems


def hash_grid_section(args) -> list[dict]:
    """Hash-grid rebuild and the seed's neighbour sum: kdsl, Warp, Numba, Taichi."""
    n, dim, dev, reps = args.points, args.grid_dim, args.device, args.reps
    radius = radius_for(n, args.neighbours)
    pts = workload(n)
    sync = (lambda: None) if dev == "cpu" else (lambda: wp.synchronize_device(dev))
    row, ours = _run_side(wp, "kdsl", pts, radius, dim, dev, reps, sync)
    row["mean_neighbours"] = float(ours["count"].mean()) - 1.0  # without the point itself
    rows, problems = [row], check_counts(ours["count"], pts, radius)
    sides = [_warp_side(pts, radius, dim, dev, reps, ours)]
    if dev == "cpu" and not getattr(args, "no_peers", False):
        sides.append(_peer_sides(pts, radius, dim, reps, ours))
    for side_rows, side_problems in sides:
        rows += side_rows
        problems += side_problems
    if problems:
        sys.exit("\n".join(problems))
    return rows


def print_hash_grid(rows: list[dict]) -> None:
    """The hash-grid section's table (ms) and kdsl's speed-ups over each peer."""
    r0, peers = rows[0], rows[1:]
    print(f"{r0['points']:,} points in the unit box, radius {r0['radius']:.4f} (mean "
          f"{r0['mean_neighbours']:.1f} neighbours), {r0['grid_dim']}^3 grid on "
          f"{r0['device']}; median ms")  # fmt: skip
    print(f"{'side':<7}{'build ms':>12}{'query ms':>12}")
    for r in rows:
        print(f"{r['side']:<7}{1e3 * r['build_s']:12.2f}{1e3 * r['query_s']:12.1f}")
    for r in peers:
        print(f"kdsl speed-up over {r['side']}: build {r['build_s'] / r0['build_s']:.2f}x, "
              f"query {r['query_s'] / r0['query_s']:.2f}x")  # fmt: skip
