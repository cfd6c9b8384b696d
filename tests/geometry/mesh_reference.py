"""Float64 brute force over every triangle: the reference the mesh query tests check
against, and the test meshes."""

from __future__ import annotations

import numpy as np


def icosphere(subdiv: int = 1, bumps: float = 0.0, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A closed, outward-wound sphere mesh (points float32 (n, 3), faces int32 (m, 3)),
    its radii jittered by ``bumps``."""
    t = (1.0 + 5**0.5) / 2
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t),
         (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]  # fmt: skip
    f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
         (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
         (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]  # fmt: skip
    pts = [np.array(p, float) / np.linalg.norm(p) for p in v]
    for _ in range(subdiv):
        cache: dict[tuple[int, int], int] = {}

        def mid(a: int, b: int, cache: dict = cache) -> int:
            key = (min(a, b), max(a, b))
            if key not in cache:
                m = pts[a] + pts[b]
                pts.append(m / np.linalg.norm(m))
                cache[key] = len(pts) - 1
            return cache[key]

        f = [g for a, b, c in f for g in ((a, mid(a, b), mid(c, a)), (b, mid(b, c), mid(a, b)),
                                          (c, mid(c, a), mid(b, c)), (mid(a, b), mid(b, c), mid(c, a)))]  # fmt: skip
    p = np.array(pts)
    if bumps:
        p *= 1.0 + bumps * np.random.default_rng(seed).uniform(-1, 1, (len(p), 1))
    return p.astype(np.float32), np.array(f, np.int32)


def closest_on_triangles(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """The closest point of each triangle ``tri`` (m, 3, 3) to ``p`` (3,): (m, 3)."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    n = np.cross(b - a, c - a)
    nn = np.einsum("ij,ij->i", n, n)
    with np.errstate(invalid="ignore", divide="ignore"):
        proj = p - (np.einsum("ij,ij->i", p - a, n) / nn)[:, None] * n
        w_a = np.einsum("ij,ij->i", np.cross(b - proj, c - proj), n) / nn
        w_b = np.einsum("ij,ij->i", np.cross(c - proj, a - proj), n) / nn
    inside = (nn > 0) & (w_a >= 0) & (w_b >= 0) & (w_a + w_b <= 1)
    best = np.where(inside[:, None], proj, np.nan)
    for s, e in ((a, b), (b, c), (c, a)):
        d = e - s
        dd = np.einsum("ij,ij->i", d, d)
        with np.errstate(invalid="ignore", divide="ignore"):
            t = np.clip(np.einsum("ij,ij->i", p - s, d) / dd, 0, 1)
        q = s + np.nan_to_num(t)[:, None] * d
        better = ~inside & ~(np.linalg.norm(best - p, axis=1) <= np.linalg.norm(q - p, axis=1))
        best = np.where(better[:, None], q, best)
    return best


def sliver(tri: np.ndarray) -> np.ndarray:
    """Warp's sliver rule (and coincident vertices), per triangle."""
    e0, e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], tri[:, 2] - tri[:, 1]
    s = (e0**2).sum(1) + (e1**2).sum(1) + (e2**2).sum(1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return ~(np.linalg.norm(np.cross(e0, e1), axis=1) / s >= 1e-6)


def closest_distances(pts: np.ndarray, faces: np.ndarray, queries: np.ndarray) -> np.ndarray:
    """Distance from each query to the mesh (slivers left out), float64."""
    tri = pts.astype(np.float64)[faces]
    tri = tri[~sliver(tri)]
    return np.array(
        [np.linalg.norm(closest_on_triangles(q, tri) - q, axis=1).min() for q in queries]
    )


def ray_hits(pts: np.ndarray, faces: np.ndarray, start: np.ndarray, d: np.ndarray) -> np.ndarray:
    """``t`` of the ray ``start + t d`` with every face (inf for a miss), Moller-Trumbore
    in float64."""
    tri = pts.astype(np.float64)[faces]
    a, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    d = d.astype(np.float64)
    h = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, h)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = start - a
        u = np.einsum("ij,ij->i", s, h) / det
        q = np.cross(s, e1)
        v = (q @ d) / det
        t = np.einsum("ij,ij->i", e2, q) / det
    ok = (det != 0) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t >= 0)
    return np.where(ok, t, np.inf)


def winding_numbers(pts: np.ndarray, faces: np.ndarray, queries: np.ndarray) -> np.ndarray:
    """The generalized winding number at each query, float64."""
    tri = pts.astype(np.float64)[faces]
    out = []
    for q in queries.astype(np.float64):
        x, y, z = tri[:, 0] - q, tri[:, 1] - q, tri[:, 2] - q
        lx, ly, lz = (np.linalg.norm(v, axis=1) for v in (x, y, z))
        num = np.einsum("ij,ij->i", x, np.cross(y, z))
        den = (lx * ly * lz + np.einsum("ij,ij->i", x, y) * lz + np.einsum("ij,ij->i", x, z) * ly
               + np.einsum("ij,ij->i", y, z) * lx)  # fmt: skip
        out.append(2 * np.arctan2(num, den).sum() / (4 * np.pi))
    return np.array(out)
