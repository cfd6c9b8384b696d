"""kdsl standard library: BVH queries (Warp's ``bvh_query_*``), in kdsl.

A ``kdsl.Bvh`` is a binary tree of boxes over the boxes (items) it was built from.
Kernels reach it through its record (``BvhRecord``, read with ``object_record``):

- nodes are numbered in depth-first preorder: node ``n`` has bounds ``lowers[n]``,
  ``uppers[n]``; its subtree is the nodes ``n .. skip[n] - 1``; a leaf holds the items
  ``items[first[n] : first[n] + count[n]]``, an inner node (``first[n] < 0``) has its
  left child at ``n + 1`` and its right child at ``skip[n + 1]``, which ``first[n]``
  names too (``first[n] = -1 - right``, ``right_child``: "right-linked" nodes, so a
  walk loads both children at once);
- ``item_lowers`` / ``item_uppers`` are the boxes the BVH was built over (the user's
  arrays), ``group_roots[g]`` is the root node of group ``g``'s subtree; ``height[0]``
  the tree's height (the most levels below the root, 0 for a leaf root or an empty
  tree), which bounds how many nodes a walk with a stack keeps waiting;
- ``nodes`` packs each node's bounds, ``first`` and ``skip`` (or a leaf's count) in 32
  bytes (``BvhNode``), which the traversal reads; ``lowers``, ``uppers`` and ``first``
  are views of it. ``nodes_ptr`` and ``items_ptr`` are the addresses of ``nodes`` and
  ``items`` (both contiguous): ``packed_nodes`` and ``tree_items`` rebuild them as
  arrays whose stride is a constant, so that a GPU walk keeps no stride in registers
  (a record's array holds its stride as a run-time value). A leaf's bounds are exactly its items' union (``refit``), so a
  leaf of one item that the query's shape touches is reported without testing the
  item's box again.

A query is a ``BvhQuery`` value; ``bvh_query_next`` advances it (an in-out argument,
as Warp's) and gives the next item whose box the query's shape touches. Traversal is
stackless: a node whose box the shape misses is skipped with ``skip[n]``, a node it
touches is entered at ``n + 1``, so a query's state is four integers (no stack in
local memory on a GPU, no dynamically indexed vector on a CPU). Items come in
depth-first order, left child first.
"""

import kdsl as wp
from kdsl.frontend.inout import inout
from kdsl.frontend.kernel import func
from kdsl.stdlib.mesh_primitives import greater, lesser, safe_inverse

__kdsl_group__ = "geometry"

__all__ = [
    "BvhQuery", "bvh_get_group_root", "bvh_query_aabb", "bvh_query_capsule", "bvh_query_next",
    "bvh_query_ray", "bvh_query_sphere",
]  # fmt: skip

#: What a query tests: its kind.
AABB, RAY, SPHERE, CAPSULE = 0, 1, 2, 3
#: Added to RAY or CAPSULE for a direction with a zero component (``_ray_box_parallel``).
PARALLEL = 4


@wp.struct(align=16)
class BvhNode:
    """A node packed for traversal (32 bytes, two 16-byte halves as Warp's: the lower
    bound and ``first``, the upper bound and ``next``; declared 16-byte aligned, so a
    GPU reads a node with two vector loads): ``first`` is a leaf's first position in
    ``items``, or for an inner node ``-1 - right`` (``inner_first``; at most -3: the
    right child follows the parent and its left child), ``next`` an inner node's
    ``skip`` or a leaf's item count. ``BvhRecord``'s ``lowers``, ``uppers`` and
    ``first`` are strided views of these fields."""

    lower: wp.vec3
    first: wp.int32
    upper: wp.vec3
    next: wp.int32


@func
def inner_first(right: int) -> int:
    """The packed ``first`` of an inner node whose right child is node ``right``."""
    return -1 - right


@func
def right_child(first: int) -> int:
    """The right child of an inner node whose packed ``first`` is ``first``."""
    return -1 - first


@wp.struct
class BvhRecord:
    """The record of a ``kdsl.Bvh`` (see the module docstring)."""

    tag: wp.uint64
    lowers: wp.array(dtype=wp.vec3)
    uppers: wp.array(dtype=wp.vec3)
    skip: wp.array(dtype=wp.int32)
    first: wp.array(dtype=wp.int32)
    count: wp.array(dtype=wp.int32)
    items: wp.array(dtype=wp.int32)
    item_lowers: wp.array(dtype=wp.vec3)
    item_uppers: wp.array(dtype=wp.vec3)
    group_roots: wp.array(dtype=wp.int32)
    root: wp.int32
    nodes: wp.array(dtype=BvhNode)
    nodes_ptr: wp.uint64  # the address of ``nodes`` (contiguous): ``packed_nodes``
    items_ptr: wp.uint64  # the address of ``items`` (contiguous): ``tree_items``
    height: wp.array(dtype=wp.int32)  # one element: the tree's height (see the docstring)


@func
def packed_nodes(rec: BvhRecord) -> wp.array(dtype=BvhNode):
    """``rec.nodes`` made from its address: the same elements, indexed with a constant
    stride (see the module docstring)."""
    return wp.array(ptr=rec.nodes_ptr, shape=(rec.nodes.shape[0],), dtype=BvhNode)


@func
def tree_items(rec: BvhRecord) -> wp.array(dtype=wp.int32):
    """``rec.items`` made from its address (as ``packed_nodes``)."""
    return wp.array(ptr=rec.items_ptr, shape=(rec.items.shape[0],), dtype=wp.int32)


@wp.struct
class BvhQuery:
    """A query in progress against a ``kdsl.Bvh`` (Warp's ``bvh_query_t``).

    ``a``, ``b`` and ``radius`` hold the query's shape: the box ``[a, b]``, the ray
    ``a + t b``, the sphere at ``a``, the capsule swept from ``a`` along ``b``.
    """

    bvh: wp.uint64
    kind: wp.int32
    a: wp.vec3
    b: wp.vec3
    inv_b: wp.vec3
    radius: wp.float32
    node: wp.int32
    stop: wp.int32
    leaf_pos: wp.int32
    leaf_end: wp.int32


@func
def _bvh_query(
    id: wp.uint64, kind: wp.int32, a: wp.vec3, b: wp.vec3, radius: float, root: int
) -> BvhQuery:
    q = BvhQuery()
    q.bvh = id
    q.kind = kind
    q.a = a
    q.b = b
    q.inv_b = wp.vec3(safe_inverse(b[0]), safe_inverse(b[1]), safe_inverse(b[2]))
    swept = kind == RAY
    swept = swept or kind == CAPSULE
    if swept and (b[0] == 0.0 or b[1] == 0.0 or b[2] == 0.0):
        q.kind = kind + PARALLEL
    q.radius = radius
    rec = wp.object_record(id, BvhRecord)
    start = root
    if start < 0:
        start = rec.root
    q.node = start
    q.stop = start
    if start >= 0:  # not an empty BVH
        q.stop = rec.skip[start]
    q.leaf_pos = 0
    q.leaf_end = 0
    return q


@func
def bvh_query_aabb(id: wp.uint64, low: wp.vec3, high: wp.vec3, root: int = -1) -> BvhQuery:
    """A query for the items whose box overlaps ``[low, high]`` (closed boxes: touching
    counts), from node ``root`` (-1: the BVH's root). Advance it with ``bvh_query_next``."""
    return _bvh_query(id, AABB, low, high, 0.0, root)


@func
def bvh_query_ray(id: wp.uint64, start: wp.vec3, dir: wp.vec3, root: int = -1) -> BvhQuery:
    """A query for the items whose box the ray ``start + t * dir`` (``t >= 0``, and ``t <=
    max_dist`` of ``bvh_query_next``) meets. ``dir`` need not be normalized."""
    return _bvh_query(id, RAY, start, dir, 0.0, root)


@func
def bvh_query_sphere(id: wp.uint64, center: wp.vec3, radius: float, root: int = -1) -> BvhQuery:
    """A query for the items whose box is within ``radius`` of ``center``."""
    return _bvh_query(id, SPHERE, center, wp.vec3(0.0), radius, root)


@func
def bvh_query_capsule(
    id: wp.uint64, start: wp.vec3, dir: wp.vec3, radius: float, root: int = -1
) -> BvhQuery:
    """A conservative capsule sweep: the items whose box, grown by ``radius``, the ray
    ``start + t * dir`` (``0 <= t <= max_dist``) meets."""
    return _bvh_query(id, CAPSULE, start, dir, radius, root)


@func
def _ray_box(
    lo: wp.vec3, hi: wp.vec3, start: wp.vec3, inv: wp.vec3, max_t: float, closed: bool
) -> bool:
    """Whether the ray meets the closed box ``[lo, hi]`` at some ``t >= 0`` with an entry
    ``t`` below ``max_t`` (at most ``max_t`` when ``closed``: Warp's capsules; its plain
    rays are half-open)."""
    t0 = wp.cw_mul(lo - start, inv)
    t1 = wp.cw_mul(hi - start, inv)
    tmin = greater(greater(lesser(t0[0], t1[0]), lesser(t0[1], t1[1])), lesser(t0[2], t1[2]))
    tmax = lesser(lesser(greater(t0[0], t1[0]), greater(t0[1], t1[1])), greater(t0[2], t1[2]))
    return tmin <= tmax and tmax >= 0.0 and (tmin < max_t or (closed and tmin == max_t))


@func
def _ray_box_parallel(
    lo: wp.vec3, hi: wp.vec3, start: wp.vec3, dir: wp.vec3, inv: wp.vec3, max_t: float,
    closed: bool,
) -> bool:  # fmt: skip
    """``_ray_box`` for a direction with zero components: such an axis's slab holds the
    whole ray when the start is within ``[lo, hi]`` on that axis (faces included), else
    none of it (Warp's answer: its NaN slab is ignored or its infinite one misses)."""
    t0 = wp.cw_mul(lo - start, inv)
    t1 = wp.cw_mul(hi - start, inv)
    tmin = -1.0e38
    tmax = 1.0e38
    inside = True
    for k in range(3):
        if dir[k] == 0.0:
            inside = inside and lo[k] <= start[k] and start[k] <= hi[k]
        else:
            tmin = greater(tmin, lesser(t0[k], t1[k]))
            tmax = lesser(tmax, greater(t0[k], t1[k]))
    hit = inside and tmin <= tmax and tmax >= 0.0
    return hit and (tmin < max_t or (closed and tmin == max_t))


@func
def _box_distance_sq(lo: wp.vec3, hi: wp.vec3, p: wp.vec3) -> float:
    """Squared distance from ``p`` to the closed box ``[lo, hi]`` (0 inside)."""
    total = 0.0
    for k in range(3):
        d = greater(greater(lo[k] - p[k], p[k] - hi[k]), 0.0)
        total = total + d * d
    return total


@func
def _no_nan(lo: wp.vec3, hi: wp.vec3) -> bool:
    """Whether a box has no NaN coordinate (an item with one is never reported)."""
    return (
        lo[0] == lo[0] and lo[1] == lo[1] and lo[2] == lo[2]
        and hi[0] == hi[0] and hi[1] == hi[1] and hi[2] == hi[2]
    )  # fmt: skip


@func
def _touches(q: BvhQuery, lo: wp.vec3, hi: wp.vec3, max_dist: float) -> bool:
    """Whether the query's shape touches the box ``[lo, hi]``."""
    if q.kind == AABB:
        return (
            lo[0] <= q.b[0] and hi[0] >= q.a[0] and lo[1] <= q.b[1] and hi[1] >= q.a[1]
            and lo[2] <= q.b[2] and hi[2] >= q.a[2]
        )  # fmt: skip
    if q.kind == SPHERE:
        return _box_distance_sq(lo, hi, q.a) <= q.radius * q.radius
    if q.kind == CAPSULE:
        r = wp.vec3(q.radius)
        return _ray_box(lo - r, hi + r, q.a, q.inv_b, max_dist, True)
    if q.kind == RAY:
        return _ray_box(lo, hi, q.a, q.inv_b, max_dist, False)
    if q.kind == CAPSULE + PARALLEL:
        r = wp.vec3(q.radius)
        return _ray_box_parallel(lo - r, hi + r, q.a, q.b, q.inv_b, max_dist, True)
    return _ray_box_parallel(lo, hi, q.a, q.b, q.inv_b, max_dist, False)


@func
def bvh_query_next(
    query: inout(BvhQuery), index: inout(wp.int32), max_dist: float = float("inf")
) -> bool:
    """Advance ``query`` to the next item its shape touches: writes the item's index
    (into the arrays the BVH was built from) to ``index`` and gives True, or gives False
    (``index`` unchanged) when no item is left. ``max_dist`` bounds ray and capsule
    queries (in multiples of ``dir``'s length; unbounded by default, as Warp's); it may
    only shrink during a query."""
    rec = wp.object_record(query.bvh, BvhRecord)
    found = False
    while not found:
        if query.leaf_pos < query.leaf_end:
            item = rec.items[query.leaf_pos]
            query.leaf_pos = query.leaf_pos + 1
            lo = rec.item_lowers[item]
            hi = rec.item_uppers[item]
            if _touches(query, lo, hi, max_dist) and _no_nan(lo, hi):
                index = item
                found = True
        elif query.node >= query.stop:
            break
        else:
            node = query.node
            nd = rec.nodes[node]  # bounds and links in one 32-byte load
            if nd.first >= 0:  # a leaf
                query.node = node + 1
                if _touches(query, nd.lower, nd.upper, max_dist):
                    if nd.next == 1:  # its box is its one item's: report it untested
                        if _no_nan(nd.lower, nd.upper):
                            index = rec.items[nd.first]  # noqa: F841 - in-out: the caller sees it
                            found = True
                    else:
                        query.leaf_pos = nd.first
                        query.leaf_end = nd.first + nd.next
            elif _touches(query, nd.lower, nd.upper, max_dist):
                query.node = node + 1
            else:
                query.node = nd.next
    return found


@func
def bvh_get_group_root(id: wp.uint64, group: int) -> int:
    """The root node of group ``group``'s subtree (pass it as a query's ``root``), or -1
    for a group with no items."""
    rec = wp.object_record(id, BvhRecord)
    if group < 0 or group >= rec.group_roots.shape[0]:
        return -1
    return rec.group_roots[group]
