"""The ``"sah"`` BVH constructor: top-down binned surface area heuristic, level by level.

Each segment of items (a node) with more than ``leaf_size`` items is split where the
surface area heuristic is lowest: its items' centres are binned (``BINS`` bins per
axis over the centres' bounds), and for each axis and each of the ``BINS - 1`` planes
between bins the cost ``area(left) * n_left + area(right) * n_right`` is computed from
the bins' box unions and counts (prefix and suffix scans). The best plane over the
three axes wins; a segment whose centres all fall in one bin splits at its middle,
and one of at most ``SMALL`` items at its median centre.
All segments of one level are handled together with NumPy (bin bounds by
``fmin.at``/``fmax.at``, a stable partition by ``argsort``), so the build costs a few
array passes per level. Segments of several groups split at a group boundary as in
``"median"``, so every group is one subtree. NaN boxes are binned with the lowest
bin and never enlarge a bin's bounds.
"""

from __future__ import annotations

import numpy as np

from kdsl.geometry.median import Tree, build_top_down, split_median

#: Bins per axis.
BINS = 16
#: Segments of at most this many items split at the median instead: their bins would
#: outnumber their items, and near the leaves the two splits cost about the same.
SMALL = 32


def build_sah(
    lowers: np.ndarray, uppers: np.ndarray, leaf_size: int = 1,
    groups: np.ndarray | None = None, num_groups: int | None = None,
) -> Tree:  # fmt: skip
    """Build a tree over the boxes ``lowers[i], uppers[i]`` (``(n, 3)`` arrays) by binned
    SAH (see the module docstring); ``groups`` as ``build_median``'s."""
    return build_top_down(lowers, uppers, leaf_size, groups, num_groups, _split_sah)


def _split_sah(centers, lowers, uppers, group_of, order, starts, counts, leaf_size):
    split = np.zeros(len(starts), np.int64)
    inner = counts > leaf_size
    if group_of is not None:
        last = np.maximum(starts + counts - 1, starts)
        mixed = inner & (group_of[order[starts]] != group_of[order[last]])
        if mixed.any():
            split[mixed] = split_median(centers, lowers, uppers, group_of, order,
                                        starts[mixed], counts[mixed], leaf_size)  # fmt: skip
        inner &= ~mixed
    small = inner & (counts <= SMALL)
    if small.any():
        split[small] = split_median(centers, lowers, uppers, group_of, order, starts[small],
                                    counts[small], leaf_size)  # fmt: skip
    sel = np.flatnonzero(inner & ~small)
    if len(sel):
        split[sel] = _sah_segments(centers, lowers, uppers, order, starts[sel], counts[sel])
    return split


def _area(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    d = np.maximum(hi - lo, 0.0)
    return d[..., 0] * d[..., 1] + d[..., 1] * d[..., 2] + d[..., 2] * d[..., 0]


def _sah_segments(centers, lowers, uppers, order, s, c) -> np.ndarray:
    """Split each segment ``order[s:s+c]`` (all with more than leaf_size items, one group)
    at its best SAH plane, reordering it in place; the left counts."""
    nseg = len(s)
    offsets = np.cumsum(c) - c
    seg = np.repeat(np.arange(nseg), c)
    pos = np.repeat(s - offsets, c) + np.arange(c.sum())
    items = order[pos]
    cen = centers[items]
    blo = np.ascontiguousarray(lowers[items].T, dtype=np.float64)  # (3, items)
    bhi = np.ascontiguousarray(uppers[items].T, dtype=np.float64)
    clo = np.fmin.reduceat(cen, offsets, axis=0)
    chi = np.fmax.reduceat(cen, offsets, axis=0)
    span = np.nan_to_num(chi - clo, nan=0.0, posinf=0.0)
    scale = np.where(span > 0, BINS / np.where(span > 0, span, 1.0), 0.0)
    with np.errstate(invalid="ignore"):
        f = np.nan_to_num((cen - clo[seg]) * scale[seg], nan=0.0, posinf=BINS, neginf=0.0)
    bins = np.clip(f.astype(np.int64), 0, BINS - 1)  # (items, 3)
    best_cost = np.full(nseg, np.inf)
    best_axis = np.zeros(nseg, np.int64)
    best_plane = np.zeros(nseg, np.int64)
    for axis in range(3):
        key = seg * BINS + bins[:, axis]
        n_bin = np.bincount(key, minlength=nseg * BINS).reshape(nseg, BINS)
        lo_bin = np.full((3, nseg * BINS), np.inf)
        hi_bin = np.full((3, nseg * BINS), -np.inf)
        for k in range(3):  # 1-d ufunc.at takes NumPy's fast path (2-d is ~10x slower)
            np.fmin.at(lo_bin[k], key, blo[k])
            np.fmax.at(hi_bin[k], key, bhi[k])
        lo_bin = lo_bin.T.reshape(nseg, BINS, 3)
        hi_bin = hi_bin.T.reshape(nseg, BINS, 3)
        left_lo = np.minimum.accumulate(lo_bin, axis=1)[:, :-1]
        left_hi = np.maximum.accumulate(hi_bin, axis=1)[:, :-1]
        right_lo = np.minimum.accumulate(lo_bin[:, ::-1], axis=1)[:, ::-1][:, 1:]
        right_hi = np.maximum.accumulate(hi_bin[:, ::-1], axis=1)[:, ::-1][:, 1:]
        n_left = np.cumsum(n_bin, axis=1)[:, :-1]
        n_right = c[:, None] - n_left
        with np.errstate(invalid="ignore"):
            cost = _area(left_lo, left_hi) * n_left + _area(right_lo, right_hi) * n_right
        cost = np.where((n_left > 0) & (n_right > 0), np.nan_to_num(cost, nan=np.inf), np.inf)
        plane = np.argmin(cost, axis=1)
        value = cost[np.arange(nseg), plane]
        better = value < best_cost
        best_cost[better], best_axis[better], best_plane[better] = (
            value[better],
            axis,
            plane[better],
        )
    found = np.isfinite(best_cost)
    right = bins[np.arange(len(items)), best_axis[seg]] > best_plane[seg]
    right &= found[seg]  # no plane: keep the order, split at the middle
    perm = np.argsort(seg * 2 + right, kind="stable")
    order[pos] = items[perm]
    n_right = np.bincount(seg, weights=right, minlength=nseg).astype(np.int64)
    return np.where(found, c - n_right, c // 2)
