"""The hash-grid workload in Numba (``@njit(parallel=True)``): Warp's wrapped grid of
``dim^3`` buckets with cell width ``radius``, built by a counting sort, and the seed's
neighbour sum over the 27 cells around each point. Imported only when Numba is
installed (the ``bench`` extra); CPU only.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

from .harness import median_seconds

NAME = "numba"
F = np.float32


@njit(inline="always")
def _bucket(x, y, z, dim):
    return ((z % dim) * dim + y % dim) * dim + x % dim  # Python's %: never negative


@njit(parallel=True)
def _keys(points, inv, dim, keys):
    for i in prange(points.shape[0]):
        x = np.int64(np.floor(points[i, 0] * inv))
        y = np.int64(np.floor(points[i, 1] * inv))
        z = np.int64(np.floor(points[i, 2] * inv))
        keys[i] = _bucket(x, y, z, dim)


@njit(parallel=True)
def _clear(counts):
    for c in prange(counts.shape[0]):
        counts[c] = 0


@njit
def _counting_sort(keys, starts, ends, order):
    """Points in bucket order: bucket ``c`` holds ``order[starts[c]:ends[c]]``."""
    for k in keys:
        ends[k] += 1
    total = 0
    for c in range(ends.shape[0]):
        starts[c] = total
        total += ends[c]
        ends[c] = starts[c]
    for i in range(keys.shape[0]):
        order[ends[keys[i]]] = i
        ends[keys[i]] += 1


def build(points, radius, dim, keys, starts, ends, order) -> None:
    """Bucket ``points`` into the grid's arrays (reused between builds)."""
    _keys(points, F(1.0) / F(radius), dim, keys)
    _clear(ends)
    _counting_sort(keys, starts, ends, order)


@njit(parallel=True)
def neighbour_sum(points, radius, dim, starts, ends, order, out):
    """The seed's ``sum``: each point's sum of the points within ``radius``."""
    inv = F(1.0) / radius
    for i in prange(points.shape[0]):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        x0 = np.int64(np.floor((px - radius) * inv))
        y0 = np.int64(np.floor((py - radius) * inv))
        z0 = np.int64(np.floor((pz - radius) * inv))
        x1 = np.int64(np.floor((px + radius) * inv))
        y1 = np.int64(np.floor((py + radius) * inv))
        z1 = np.int64(np.floor((pz + radius) * inv))
        sx = sy = sz = F(0.0)
        for z in range(z0, z1 + 1):
            for y in range(y0, y1 + 1):
                for x in range(x0, x1 + 1):
                    c = _bucket(x, y, z, dim)
                    for k in range(starts[c], ends[c]):
                        j = order[k]
                        qx, qy, qz = points[j, 0], points[j, 1], points[j, 2]
                        dx, dy, dz = px - qx, py - qy, pz - qz
                        if np.sqrt(dx * dx + dy * dy + dz * dz) < radius:
                            sx += qx
                            sy += qy
                            sz += qz
        out[i, 0], out[i, 1], out[i, 2] = sx, sy, sz


def run(pts: np.ndarray, radius: float, dim: int, reps: int) -> tuple[dict, np.ndarray]:
    """Median build and query seconds on ``pts`` (float32, (n, 3)), and the sums."""
    n, cells = len(pts), dim**3
    keys, order = np.empty(n, np.int64), np.empty(n, np.int64)
    starts, ends = np.zeros(cells, np.int64), np.zeros(cells, np.int64)
    out = np.zeros((n, 3), np.float32)
    r = F(radius)
    def rebuild():
        build(pts, r, dim, keys, starts, ends, order)

    def query():
        neighbour_sum(pts, r, dim, starts, ends, order, out)

    times = {
        "build_s": median_seconds(rebuild, reps, lambda: None),
        "query_s": median_seconds(query, reps, lambda: None),
        "threads": numba.get_num_threads(),
    }
    return times, out
