"""The ``"median"`` BVH constructor: top-down splits at the median centroid, level by level.

All nodes of one tree level are split at once with NumPy (a segmented sort of the
items' centroids along each node's longest centroid axis), so the build costs a few
array passes per level rather than Python work per node. With groups, items are
first ordered by group and a node holding several groups splits at the group
boundary nearest its middle, so every group ends up as one subtree.

The build numbers nodes level by level; ``Tree`` renumbers them in depth-first
preorder, the layout ``kdsl.stdlib.bvh`` documents (``skip``, ``first``, ``count``),
and keeps per node its ``level`` (for the bottom-up bounds pass, ``refit_bounds``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Tree:
    """A BVH's topology on the host, nodes in depth-first preorder (bounds come from
    ``refit_bounds``). An inner node's left child is the next node; ``skip[n]`` is the
    first node after ``n``'s subtree."""

    skip: np.ndarray  # int32 per node
    first: np.ndarray  # int32 per node: a leaf's first position in ``items``, -1 inner
    count: np.ndarray  # int32 per node: a leaf's number of items, 0 inner
    right: np.ndarray  # int32 per node: an inner node's right child, -1 for a leaf
    items: np.ndarray  # int32 item indices in leaf order
    level: np.ndarray  # int32 depth of each node
    group_roots: np.ndarray  # int32 root node of each group (-1 for an empty group)

    @property
    def num_nodes(self) -> int:
        """Number of nodes."""
        return len(self.skip)


def preorder_tree(
    left: np.ndarray, right: np.ndarray, level: np.ndarray, items: np.ndarray,
    group_roots: np.ndarray,
) -> Tree:  # fmt: skip
    """A ``Tree`` from a tree numbered in any top-down order (children after parents):
    ``left[n] >= 0`` gives inner nodes' children, a leaf has ``left = -first - 1`` and
    ``right = count``."""
    m = len(left)
    inner = left >= 0
    size = np.ones(m, np.int64)
    by_depth = np.argsort(level, kind="stable")
    for d in range(int(level.max(initial=0)), -1, -1):  # subtree sizes, bottom up
        at = by_depth[level[by_depth] == d]
        at = at[inner[at]]
        size[at] = 1 + size[left[at]] + size[right[at]]
    pre = np.zeros(m, np.int64)
    for d in range(int(level.max(initial=0)) + 1):  # preorder numbers, top down
        at = by_depth[level[by_depth] == d]
        at = at[inner[at]]
        pre[left[at]] = pre[at] + 1
        pre[right[at]] = pre[at] + 1 + size[left[at]]
    skip = np.empty(m, np.int32)
    first = np.full(m, -1, np.int32)
    count = np.zeros(m, np.int32)
    rchild = np.full(m, -1, np.int32)
    skip[pre] = pre + size
    first[pre[~inner]] = -left[~inner] - 1
    count[pre[~inner]] = right[~inner]
    rchild[pre[inner]] = pre[right[inner]]
    lvl = np.empty(m, np.int32)
    lvl[pre] = level
    roots = np.where(group_roots >= 0, pre[np.maximum(group_roots, 0)], -1).astype(np.int32)
    return Tree(skip, first, count, rchild, items.astype(np.int32), lvl, roots)


def build_median(
    lowers: np.ndarray, uppers: np.ndarray, leaf_size: int = 1,
    groups: np.ndarray | None = None, num_groups: int | None = None,
) -> Tree:  # fmt: skip
    """Build a tree over the boxes ``lowers[i], uppers[i]`` (``(n, 3)`` arrays); with
    ``groups`` (ids >= 0), ``num_groups`` (default: the largest id + 1) group roots."""
    return build_top_down(lowers, uppers, leaf_size, groups, num_groups, split_median)


def split_median(centers, lowers, uppers, group_of, order, starts, counts, leaf_size):
    """The median splitter of ``build_top_down`` (see ``_split_points``)."""
    return _split_points(centers, group_of, order, starts, counts, leaf_size)


def build_top_down(lowers, uppers, leaf_size, groups, num_groups, splitter) -> Tree:
    """Build a tree level by level: ``splitter(centers, lowers, uppers, group_of, order,
    starts, counts, leaf_size)`` reorders each segment ``order[starts:starts+counts]``
    in place and gives where it splits (0: a leaf); a segment of several groups must
    split at a group boundary."""
    n = len(lowers)
    leaf_size = max(1, int(leaf_size))
    centers = 0.5 * (lowers.astype(np.float64) + uppers.astype(np.float64))
    if groups is not None:
        group_of = np.asarray(groups, dtype=np.int64)
        order = np.argsort(group_of, kind="stable")
        ngroups = num_groups if num_groups is not None else int(group_of.max(initial=-1)) + 1
    else:
        group_of, order, ngroups = None, np.arange(n), 0
    cap = max(1, 2 * n - 1)
    left = np.zeros(cap, np.int32)
    right = np.zeros(cap, np.int32)
    level = np.zeros(cap, np.int32)
    group_roots = np.full(ngroups, -1, np.int32)
    if n == 0:
        return preorder_tree(left[:0], right[:0], level[:0], order, group_roots)
    starts, counts, nodes = np.array([0]), np.array([n]), np.array([0])
    next_node, depth = 1, 0
    while len(starts):
        level[nodes] = depth
        if group_of is not None:
            _note_group_roots(group_of, order, starts, counts, nodes, group_roots)
        split = splitter(centers, lowers, uppers, group_of, order, starts, counts, leaf_size)
        leaf = split == 0
        left[nodes[leaf]] = -(starts[leaf] + 1)
        right[nodes[leaf]] = counts[leaf]
        s, c, nd, mid = starts[~leaf], counts[~leaf], nodes[~leaf], split[~leaf]
        k = len(s)
        kids = next_node + np.arange(2 * k)
        left[nd], right[nd] = kids[0::2], kids[1::2]
        next_node += 2 * k
        starts = np.stack([s, s + mid], axis=1).ravel()
        counts = np.stack([mid, c - mid], axis=1).ravel()
        nodes = kids
        depth += 1
    m = next_node
    return preorder_tree(left[:m], right[:m], level[:m], order, group_roots)


def _note_group_roots(group_of, order, starts, counts, nodes, group_roots) -> None:
    """Record the nodes whose items are exactly one whole group."""
    first = group_of[order[starts]]
    last = group_of[order[starts + counts - 1]]
    for node, g, h in zip(nodes, first, last):
        if g == h and group_roots[g] < 0:
            group_roots[g] = node


def _split_points(centers, group_of, order, starts, counts, leaf_size) -> np.ndarray:
    """Per segment, where its items split (0: it is a leaf); reorders ``order`` in place."""
    split = np.where(counts > leaf_size, counts // 2, 0)
    inner = np.flatnonzero(split)
    if not len(inner):
        return split
    s, c = starts[inner], counts[inner]
    seg = np.repeat(np.arange(len(inner)), c)
    pos = np.repeat(s - np.cumsum(c) + c, c) + np.arange(c.sum())  # item positions
    items = order[pos]
    if group_of is not None:
        g = group_of[items]
        mixed = g[np.cumsum(c) - 1] != g[np.cumsum(c) - c]
    else:
        mixed = np.zeros(len(inner), bool)
    pts = centers[items]
    bounds_at = np.cumsum(c) - c
    lo = np.fmin.reduceat(pts, bounds_at, axis=0)  # fmin/fmax: NaN centres are skipped
    hi = np.fmax.reduceat(pts, bounds_at, axis=0)
    axis = np.argmax(hi - lo, axis=1)
    key = pts[np.arange(len(pts)), axis[seg]]
    if group_of is not None:
        # Mixed segments sort by group only (their spatial key does not matter).
        key = np.where(mixed[seg], 0.0, key)
        perm = np.lexsort((key, group_of[items], seg))
    else:
        # One sort of seg + key scaled into [0, 1) (a lexsort of (key, seg) costs 5x more):
        # segments are disjoint position ranges, so the order only moves items within one.
        span = (hi - lo)[np.arange(len(inner)), axis]
        low = lo[np.arange(len(inner)), axis]
        scale = np.where(span > 0, 0.5 / np.where(span > 0, span, 1.0), 0.0)
        with np.errstate(invalid="ignore"):  # NaN or infinite centres sort first
            frac = np.nan_to_num((key - low[seg]) * scale[seg], nan=0.0, posinf=0.5, neginf=0.0)
        perm = np.argsort(seg + np.clip(frac, 0.0, 0.5))
    order[pos] = items[perm]
    for j in np.flatnonzero(mixed):  # split a multi-group node at the boundary nearest mid
        gs = group_of[order[s[j] : s[j] + c[j]]]
        edges = np.flatnonzero(gs[1:] != gs[:-1]) + 1
        split[inner[j]] = edges[np.argmin(np.abs(edges - c[j] // 2))]
    return split


def refit_bounds(
    tree: Tree, lowers: np.ndarray, uppers: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Node bounds of ``tree`` over the item boxes: leaves from their items, inner nodes
    from their children, bottom up."""
    m = tree.num_nodes
    lo = np.empty((m, 3), np.float32)
    hi = np.empty((m, 3), np.float32)
    if m == 0:
        return lo, hi
    leaf = np.flatnonzero(tree.first >= 0)
    first = tree.first[leaf]
    by_start = np.argsort(first)
    leaf, first = leaf[by_start], first[by_start]
    lo[leaf] = np.minimum.reduceat(lowers[tree.items], first, axis=0)
    hi[leaf] = np.maximum.reduceat(uppers[tree.items], first, axis=0)
    inner = np.flatnonzero(tree.first < 0)
    for d in range(int(tree.level.max()), -1, -1):
        at = inner[tree.level[inner] == d]
        a, b = at + 1, tree.right[at]
        lo[at] = np.minimum(lo[a], lo[b])
        hi[at] = np.maximum(hi[a], hi[b])
    return lo, hi
