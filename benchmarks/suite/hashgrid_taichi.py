"""The hash-grid workload in Taichi (its CPU backend; no ``from __future__ import
annotations``: Taichi reads kernel annotations as objects): Warp's wrapped grid of ``dim^3``
buckets with cell width ``radius``, built by an atomic counting sort (counts, a serial
prefix sum, a scatter), and the seed's neighbour sum over the 27 cells around each
point. Imported only when Taichi is installed (the ``bench`` extra).
"""


import numpy as np
import taichi as ti

from .harness import median_seconds

NAME = "taichi"


def prepare(pts: np.ndarray, radius: float, dim: int, threads: int | None = None):
    """Taichi (initialised on its CPU backend, on ``threads`` threads or all) set up on
    ``pts`` (float32, (n, 3)): ``(build, query, sums)``, the synchronized grid build, the
    synchronized neighbour sum, and a function giving the last sums."""
    extra = {} if threads is None else {"cpu_max_num_threads": threads}
    ti.init(arch=ti.cpu, default_fp=ti.f32, log_level=ti.WARN, **extra)
    n, cells = len(pts), dim**3
    points = ti.Vector.field(3, ti.f32, n)
    out = ti.Vector.field(3, ti.f32, n)
    keys, slot, order = (ti.field(ti.i32, n) for _ in range(3))
    counts, starts = ti.field(ti.i32, cells), ti.field(ti.i32, cells)
    points.from_numpy(pts)

    @ti.func
    def bucket(c):
        w = (c % dim + dim) % dim  # wrapped, never negative
        return (w[2] * dim + w[1]) * dim + w[0]

    @ti.kernel
    def count(inv: ti.f32):
        for c in counts:
            counts[c] = 0
        for i in points:
            k = bucket(ti.floor(points[i] * inv, ti.i32))
            keys[i] = k
            slot[i] = ti.atomic_add(counts[k], 1)

    @ti.kernel
    def prefix():
        ti.loop_config(serialize=True)
        total = 0
        for c in range(cells):
            starts[c] = total
            total += counts[c]

    @ti.kernel
    def scatter():
        for i in keys:
            order[starts[keys[i]] + slot[i]] = i

    def build():
        count(1.0 / radius)
        prefix()
        scatter()
        ti.sync()

    @ti.kernel
    def neighbour_sum(r: ti.f32):
        inv = 1.0 / r
        for i in points:
            p = points[i]
            lo = ti.floor((p - r) * inv, ti.i32)
            hi = ti.floor((p + r) * inv, ti.i32)
            s = ti.Vector([0.0, 0.0, 0.0], ti.f32)
            for z in range(lo[2], hi[2] + 1):
                for y in range(lo[1], hi[1] + 1):
                    for x in range(lo[0], hi[0] + 1):
                        c = bucket(ti.Vector([x, y, z]))
                        for k in range(starts[c], starts[c] + counts[c]):
                            q = points[order[k]]
                            if (p - q).norm() < r:
                                s += q
            out[i] = s

    def query():
        neighbour_sum(radius)
        ti.sync()

    return build, query, out.to_numpy


def run(pts: np.ndarray, radius: float, dim: int, reps: int) -> tuple[dict, np.ndarray]:
    """Median build and query seconds on ``pts`` (float32, (n, 3)), and the sums."""
    build, query, sums = prepare(pts, radius, dim)
    times = {
        "build_s": median_seconds(build, reps, lambda: None),
        "query_s": median_seconds(query, reps, lambda: None),
    }
    return times, sums()
