"""kdsl standard library: triangle mesh queries (Warp's ``mesh_*``), in kdsl.

A ``kdsl.Mesh`` is reached from a kernel through its record (``MeshRecord``): its
points, velocities (empty when it has none) and flat triangle indices, and the id of
the ``kdsl.Bvh`` over its triangles' boxes, whose layout ``kdsl.stdlib.bvh`` documents.
The queries walk that BVH's packed nodes (``BvhNode``) stacklessly (a box the query
cannot use is jumped over with ``skip``), so their state is a few integers and floats,
with two exceptions where the visiting order pays: the closest point and the closest
ray hit visit the nearer child first (by box distance, by entry ``t``; the nodes are
right-linked, so both children load at once), the other waiting on a stack of
``WALK_STACK`` entries (a thread-local array; for the closest point, deeper trees fall
back to a stackless pass in the same loop, so the walk tests leaves at one place; the
closest hit walks a tree taller than its stack, ``BvhRecord.height``, with a
stackless pass alone). Neither order changes an answer. The stackless walks alternate two loops
("while-while", Aila and Laine 2009): nodes up to the next leaf to test
(``_next_near_leaf``), then that leaf's faces; the ordered ones descend to a leaf in an
inner loop. On a GPU the threads of a warp then test faces together. A leaf's faces are
read from the record's ``tri`` (each face's corners copied in the BVH's item order, so
a leaf's faces are consecutive; ``kdsl.geometry.mesh_tree_points``), and a face's number
is loaded only for a face that would be the answer. The ray walks and the closest
point's binary walk read the nodes, the corners and the face numbers through arrays
made from the records' addresses (``packed_nodes``, ``_tri_copy``: constant strides,
no stride in registers).

Semantics are Warp 1.19's (signs, barycentric ``(u, v)`` weighing a face's first and
second vertices, strict ``max_dist``/``max_t`` bounds). Where Warp's answer depends on
its tree's visiting order, kdsl's does not: among faces at the same distance (or the
same ray ``t``) the lowest face index wins. Point queries skip sliver triangles as
Warp does (``mesh_primitives.is_sliver``). A NaN query point or ray finds nothing.
docs/geometry.md ("Meshes") lists the choices.

Each point and ray query comes in two forms, as in Warp: the struct-returning one
(``mesh_query_point(id, p, max_dist) -> MeshQueryPoint``) and the older one with
out-arguments (``mesh_query_point(id, p, max_dist, sign, face, u, v) -> bool``), told
apart by their number of arguments.
"""

import kdsl as wp
from kdsl.frontend.inout import inout
from kdsl.frontend.kernel import func
from kdsl.stdlib.bvh import (
    BvhNode,
    BvhQuery,
    BvhRecord,
    bvh_get_group_root,
    bvh_query_aabb,
    bvh_query_next,
    bvh_query_sphere,
    packed_nodes,
    right_child,
    tree_items,
)
from kdsl.stdlib.mesh_primitives import (
    RayShear,
    box_distance_sq,
    box_furthest_distance_sq,
    closest_point_to_triangle,
    furthest_point_to_triangle,
    intersect_ray_triangle,
    is_sliver,
    ray_box_enter,
    ray_box_entry,
    ray_shear,
    safe_inverse,
    triangle_solid_angle,
)
from kdsl.stdlib.mesh_wide import WIDE_OVERFLOW, wide_closest_face, wide_furthest_face
from kdsl.stdlib.random import rand_init, randf

__kdsl_group__ = "geometry"

__all__ = [
    "MeshQuery", "MeshQueryAABB", "MeshQueryPoint", "MeshQueryRay", "MeshRecord",
    "mesh_eval_face_normal", "mesh_eval_position", "mesh_eval_velocity", "mesh_get",
    "mesh_get_bvh", "mesh_get_group_root", "mesh_get_index", "mesh_get_point",
    "mesh_get_velocity", "mesh_query_aabb", "mesh_query_aabb_next",
    "mesh_query_furthest_point_no_sign", "mesh_query_next", "mesh_query_point",
    "mesh_query_point_no_sign", "mesh_query_point_sign_normal",
    "mesh_query_point_sign_parity", "mesh_query_point_sign_winding_number",
    "mesh_query_ray", "mesh_query_ray_anyhit", "mesh_query_ray_count_intersections",
    "mesh_query_sphere",
]  # fmt: skip

#: What a ``MeshQueryAABB`` tests.
AABB, SPHERE = 0, 1
#: The largest finite float32 (Warp's FLT_MAX), the bound of an unbounded ray.
FLT_MAX = 3.402823466e38
#: Nodes the ordered walks (closest point, closest ray hit) keep waiting: at most one
#: per level of the tree below the root (a 200k-face mesh's tree is 24 deep); deeper
#: trees fall back to a stackless pass. Warp's stack holds 32 too. The stacks are
#: ``kdsl.ext.empty`` arrays: every entry is written before it is read, so no query
#: pays for a fill (Warp's are uninitialized C arrays too).
WALK_STACK = 32
#: 1 / (4 pi): solid angle to winding number.
INV_4PI = 0.07957747154594767


@wp.struct
class MeshRecord:
    """The record of a ``kdsl.Mesh`` (``mesh_get`` returns it): ``points``,
    ``velocities`` (empty without velocities), ``indices`` (three per face), ``bvh``
    (the id of the BVH over the faces' boxes), ``tri`` (each face's corners in the
    BVH's item order: ``tri[3 k + j]`` is corner ``j`` of face ``items[k]``,
    ``kdsl.geometry.mesh_tree_points``), ``wide`` (the id of the mesh's 4-wide tree,
    ``kdsl.stdlib.mesh_wide``; 0 on a device that keeps none), ``tri_ptr`` (the address
    of ``tri``, which is contiguous: an array made from it in a kernel, ``array(ptr=...)``,
    has a constant stride, see ``kdsl.stdlib.bvh.packed_nodes``) and per-mesh constants."""

    tag: wp.uint64
    points: wp.array(dtype=wp.vec3)
    velocities: wp.array(dtype=wp.vec3)
    indices: wp.array(dtype=wp.int32)
    tri: wp.array(dtype=wp.vec3)
    bvh: wp.uint64
    num_points: wp.int32
    num_tris: wp.int32
    edge_length_sum: wp.array(dtype=wp.float32)  # one element: the faces' edges, summed
    support_winding_number: wp.int32
    wide: wp.uint64
    tri_ptr: wp.uint64  # the address of ``tri`` (contiguous)


@wp.struct
class MeshQueryPoint:
    """A point query's answer (Warp's ``MeshQueryPoint``): ``result`` (a face was found),
    ``sign`` (< 0 inside, >= 0 outside; 0 for the unsigned queries), ``face`` and the
    barycentric ``u``, ``v`` of the closest (or furthest) point."""

    result: wp.bool
    sign: wp.float32
    face: wp.int32
    u: wp.float32
    v: wp.float32


@wp.struct
class MeshQueryRay:
    """A ray query's answer (Warp's ``MeshQueryRay``): ``result``, ``sign`` (> 0: the
    ray hit the face's front), ``face``, ``t`` (in multiples of ``dir``), the
    barycentric ``u``, ``v`` of the hit and the face's unit ``normal``."""

    result: wp.bool
    sign: wp.float32
    face: wp.int32
    t: wp.float32
    u: wp.float32
    v: wp.float32
    normal: wp.vec3


@wp.struct
class MeshQueryAABB:
    """A box or sphere query over a mesh's faces in progress (Warp's ``MeshQuery``);
    advance it with ``mesh_query_next``."""

    mesh: wp.uint64
    kind: wp.int32
    center: wp.vec3
    radius: wp.float32
    bvh: BvhQuery


#: Warp's name for a query of either kind.
MeshQuery = MeshQueryAABB


# -- faces -------------------------------------------------------------------------


@func
def _vertex(rec: MeshRecord, face: int, corner: int) -> wp.vec3:
    return rec.points[rec.indices[face * 3 + corner]]


@func
def _corner(rec: MeshRecord, k: int, corner: int) -> wp.vec3:
    """Corner ``corner`` of the face at position ``k`` of the BVH's items (the leaves'
    copy, ``rec.tri``: no index loads)."""
    return rec.tri[k * 3 + corner]


@func
def _tri_copy(rec: MeshRecord) -> wp.array(dtype=wp.vec3):
    """``rec.tri`` made from its address: indexed with a constant stride, so a GPU walk
    keeps no stride in registers (``kdsl.stdlib.bvh.packed_nodes``)."""
    return wp.array(ptr=rec.tri_ptr, shape=(rec.tri.shape[0],), dtype=wp.vec3)


@func
def _face_point(a: wp.vec3, b: wp.vec3, c: wp.vec3, point: wp.vec3, far: bool) -> wp.vec3:
    """The point of triangle ``(a, b, c)`` closest to ``point`` (``far``: furthest from
    it, a vertex)."""
    uv = wp.vec2(0.0)
    if far:
        uv = furthest_point_to_triangle(a, b, c, point)
    else:
        uv = closest_point_to_triangle(a, b, c, point)
    return a * uv[0] + b * uv[1] + c * (1.0 - uv[0] - uv[1])


@func
def _point_on_face(rec: MeshRecord, face: int, u: float, v: float) -> wp.vec3:
    a = _vertex(rec, face, 0)
    b = _vertex(rec, face, 1)
    c = _vertex(rec, face, 2)
    return a * u + b * v + c * (1.0 - u - v)


@func
def _face_bary(rec: MeshRecord, face: int, point: wp.vec3) -> wp.vec2:
    return closest_point_to_triangle(
        _vertex(rec, face, 0), _vertex(rec, face, 1), _vertex(rec, face, 2), point
    )


@func
def _root_range(bvh: BvhRecord, root: int) -> wp.vec2i:
    """The node range ``[start, stop)`` of the subtree at ``root`` (-1: the whole tree)."""
    start = root
    if start < 0:
        start = bvh.root
    if start < 0:  # an empty mesh
        return wp.vec2i(0, 0)
    return wp.vec2i(start, bvh.skip[start])


@func
def _skip(nd: BvhNode, node: int) -> int:
    """The node after the subtree of ``node`` (packed as ``nd``): an inner node's
    ``skip``, a leaf's successor."""
    if nd.first < 0:
        return nd.next
    return node + 1


# -- closest and furthest points -----------------------------------------------------


@wp.struct
class _Closest:
    """The best face found so far by a closest-point search and its squared distance."""

    dist_sq: wp.float32
    face: wp.int32


@func
def _closest_in_leaf(
    tri: wp.array(dtype=wp.vec3), items: wp.array(dtype=wp.int32), first: int, count: int,
    point: wp.vec3, best: _Closest,
) -> _Closest:  # fmt: skip
    """``best`` updated with the ``count`` faces of a leaf from ``items[first]`` (``tri``:
    the record's ``tri``, ``items`` the BVH's): a face replaces it when strictly closer,
    or as close with a lower index; slivers are left out."""
    out = best
    for k in range(first, first + count):
        a = tri[k * 3]
        b = tri[k * 3 + 1]
        c = tri[k * 3 + 2]
        uv = closest_point_to_triangle(a, b, c, point)
        q = a * uv[0] + b * uv[1] + c * (1.0 - uv[0] - uv[1])
        d = wp.length_sq(q - point)
        if d <= out.dist_sq:  # the face's number is loaded only here
            f = items[k]
            if d < out.dist_sq or (out.face >= 0 and f < out.face):  # noqa: SIM102
                # The sliver test (a square root and a division) only for a face that wins.
                if not is_sliver(a, b, c):
                    out.dist_sq = d
                    out.face = f
    return out


@func
def _wait(
    nodes: wp.array(dtype=wp.int32), keys: wp.array(dtype=wp.float32), count: int, node: int,
    key: float,
) -> int:  # fmt: skip
    """Puts ``node`` with its ``key`` (box distance, entry ``t``) on an ordered walk's
    stack of ``count`` entries: the new count, ``WALK_STACK + 1`` when the stack was
    full (the node is dropped; the walk then owes a stackless pass)."""
    if count < WALK_STACK:
        nodes[count] = node
        keys[count] = key
    return count + 1


@func
def _closest_face(id: wp.uint64, point: wp.vec3, max_dist: float) -> int:
    """The face closest to ``point`` at a distance strictly below ``max_dist`` (lowest
    index among ties; slivers left out), or -1.

    Nearer child first (Warp's order): at an inner node both children's boxes are
    tested (both loads at once: the node names its right child, ``right_child``), the
    walk goes on into the nearer one (its node, loaded to order the two, is not loaded
    again) and the other waits on a stack of ``WALK_STACK`` entries with its box
    distance, dropped when it comes off the stack beyond the closest distance found
    meanwhile. Each step of the outer loop takes a node off the stack and descends from
    it to a leaf, then tests that leaf's faces (on a GPU the descent's inner loop keeps
    a warp's threads in step; visiting one node per step measured 25% slower on an
    H200). A tree deeper than the stack finishes with a stackless pass bounded by the
    distance found (``sweep``: its next node), in the same loop, so that the leaf test
    is inlined once: the answer never depends on the order.

    A mesh with a 4-wide tree (the CPU's, ``kdsl.geometry.wide_tree``) is walked there
    instead, with the same answer; this walk then runs only when that one cannot (and
    only the backends that take the wide walk compile it: ``kdsl.ir.ops_target``)."""
    rec = wp.object_record(id, MeshRecord)
    if rec.wide != wp.uint64(0):
        wide = wide_closest_face(rec.wide, point, max_dist)
        if wide != WIDE_OVERFLOW:
            return wide
    bvh = wp.object_record(rec.bvh, BvhRecord)
    tree = packed_nodes(bvh)  # (the arrays by address: constant strides)
    tri = _tri_copy(rec)
    items = tree_items(bvh)
    best = _Closest()
    best.dist_sq = max_dist * max_dist
    best.face = -1
    span = _root_range(bvh, -1)
    nodes = wp.ext.empty(WALK_STACK, dtype=wp.int32)  # written before read: no zero fill
    dists = wp.ext.empty(WALK_STACK, dtype=wp.float32)
    count = 0
    sweep = span[1]  # the stackless pass's next node: none until the stack overflows
    if span[0] < span[1]:
        nodes[0] = span[0]  # at distance 0: its children are tested against the bound
        dists[0] = 0.0
        count = 1
    while count > 0 or sweep < span[1]:
        first = 0  # the leaf to test: its faces [first, first + count)
        count_in = 0
        if count == 0:  # after an overflow, the stackless pass: its next leaf
            step = _next_near_leaf(tree, sweep, span[1], point, best.dist_sq)
            sweep = step[2]
            first = step[0]
            count_in = step[1]
        else:
            count = count - 1
            node = nodes[count]
            if dists[count] <= best.dist_sq:
                nd = tree[node]
                inner = nd.first < 0
                while inner:  # down the nearer child, the other onto the stack
                    near = node + 1
                    far = right_child(nd.first)  # (right-linked: both loads at once)
                    near_nd = tree[near]
                    far_nd = tree[far]
                    d_near = box_distance_sq(near_nd.lower, near_nd.upper, point)
                    d_far = box_distance_sq(far_nd.lower, far_nd.upper, point)
                    if d_far < d_near:
                        tmp = near
                        near = far
                        far = tmp
                        near_nd = far_nd
                        tmp_d = d_near
                        d_near = d_far
                        d_far = tmp_d
                    if d_far <= best.dist_sq:  # (false for NaN: a NaN point prunes every box)
                        count = _wait(nodes, dists, count, far, d_far)
                        if count > WALK_STACK:  # full: a stackless pass once it is empty
                            count = WALK_STACK
                            sweep = span[0]
                    inner = False
                    if d_near <= best.dist_sq:
                        node = near
                        nd = near_nd
                        inner = nd.first < 0
                if nd.first >= 0:  # a leaf reached (an inner node: both children pruned)
                    first = nd.first
                    count_in = nd.next
        best = _closest_in_leaf(tri, items, first, count_in, point, best)
    return best.face


@wp.func_grad(_closest_face)
def _adj_closest_face(id: wp.uint64, point: wp.vec3, max_dist: float, adj_ret: int):
    """No gradient: the face found is piecewise constant in the point (the barycentrics,
    computed outside the search, carry the gradient). The backward pass replays the
    search whole rather than differentiating its loop, which reads a thread-local
    stack."""
    pass


@func
def _next_near_leaf(
    nodes: wp.array(dtype=BvhNode), node: int, stop: int, point: wp.vec3, bound_sq: float
) -> wp.vec3i:
    """The walk from ``node`` to the next leaf before ``stop`` whose box lies within
    ``sqrt(bound_sq)`` of ``point``, jumping over the subtrees whose box does not:
    that leaf's ``(first, count, node after it)``, or ``(0, 0, stop)`` when there is
    none.

    A closest-point walk alternates this loop with the test of the leaf's faces
    ("while-while", Aila and Laine 2009) instead of visiting one node per iteration
    and testing faces in the iterations that reach a leaf ("if-if"): on a GPU the
    threads of a warp, each at its own node, then test faces together, not in every
    iteration where any one of them is at a leaf. The nodes visited are the same."""
    while node < stop:
        nd = nodes[node]
        if box_distance_sq(nd.lower, nd.upper, point) <= bound_sq:
            if nd.first >= 0:
                return wp.vec3i(nd.first, nd.next, node + 1)
            node = node + 1
        else:
            node = _skip(nd, node)
    return wp.vec3i(0, 0, stop)


@func
def _furthest_face(id: wp.uint64, point: wp.vec3, min_dist: float) -> int:
    """The face whose furthest vertex from ``point`` is furthest, strictly beyond
    ``min_dist`` (lowest index among ties; slivers left out), or -1 (through the
    4-wide tree where the mesh has one, as ``_closest_face``)."""
    rec = wp.object_record(id, MeshRecord)
    if rec.wide != wp.uint64(0):
        wide = wide_furthest_face(rec.wide, point, min_dist)
        if wide != WIDE_OVERFLOW:
            return wide
    bvh = wp.object_record(rec.bvh, BvhRecord)
    best = min_dist * min_dist
    if min_dist < 0.0:
        best = -1.0
    best_face = -1
    span = _root_range(bvh, -1)
    node = span[0]
    while node < span[1]:
        step = _next_far_leaf(bvh, node, span[1], point, best)
        node = step[2]
        for k in range(step[0], step[0] + step[1]):
            a = _corner(rec, k, 0)
            b = _corner(rec, k, 1)
            c = _corner(rec, k, 2)
            q = _face_point(a, b, c, point, True)
            d = wp.length_sq(q - point)
            if d >= best and not is_sliver(a, b, c):
                f = bvh.items[k]
                if d > best or (best_face >= 0 and f < best_face):
                    best = d
                    best_face = f
    return best_face


@wp.func_grad(_furthest_face)
def _adj_furthest_face(id: wp.uint64, point: wp.vec3, min_dist: float, adj_ret: int):
    """No gradient, as ``_adj_closest_face``: the backward pass replays the search whole
    (the 4-wide walk reads thread-local arrays it could not differentiate through)."""
    pass


@func
def _next_far_leaf(
    bvh: BvhRecord, node: int, stop: int, point: wp.vec3, bound_sq: float
) -> wp.vec3i:
    """``_next_near_leaf`` for the furthest point: the next leaf whose box reaches at
    least ``sqrt(bound_sq)`` from ``point``."""
    while node < stop:
        nd = bvh.nodes[node]
        if box_furthest_distance_sq(nd.lower, nd.upper, point) >= bound_sq:
            if nd.first >= 0:
                return wp.vec3i(nd.first, nd.next, node + 1)
            node = node + 1
        else:
            node = _skip(nd, node)
    return wp.vec3i(0, 0, stop)


@func
def _point_answer(id: wp.uint64, point: wp.vec3, face: int, sign: float) -> MeshQueryPoint:
    """A ``MeshQueryPoint`` for ``face`` (-1: no result). The barycentrics are computed
    here, outside the search, so gradients reach ``point`` through them alone."""
    q = _point_found(False, 0.0, 0, wp.vec2(0.0))
    if face >= 0:
        rec = wp.object_record(id, MeshRecord)
        q = _point_found(True, sign, face, _face_bary(rec, face, point))
    return q


@func
def _point_found(result: bool, sign: float, face: int, uv: wp.vec2) -> MeshQueryPoint:
    q = MeshQueryPoint()
    q.result = result
    q.sign = sign
    q.face = face
    q.u = uv[0]
    q.v = uv[1]
    return q


@func
def _write_point(
    q: MeshQueryPoint,
    inside: inout(wp.float32),
    face: inout(wp.int32),
    bary_u: inout(wp.float32),
    bary_v: inout(wp.float32),
) -> bool:
    """The out-argument forms' common tail: writes ``q``'s fields to the caller's
    variables when ``q`` holds a result (they are left alone otherwise)."""
    if q.result:
        inside = q.sign  # noqa: F841 - in-out parameters: the caller sees them
        face = q.face  # noqa: F841
        bary_u = q.u  # noqa: F841
        bary_v = q.v  # noqa: F841
    return q.result


@func
def mesh_query_point_no_sign(id: wp.uint64, point: wp.vec3, max_dist: float) -> MeshQueryPoint:
    """The closest point of mesh ``id`` to ``point``, closer than ``max_dist``, without
    the inside/outside sign (``sign`` is 0)."""
    return _point_answer(id, point, _closest_face(id, point, max_dist), 0.0)


@func
def mesh_query_point_no_sign(  # noqa: F811 - the out-argument form
    id: wp.uint64,
    point: wp.vec3,
    max_dist: float,
    face: inout(wp.int32),
    bary_u: inout(wp.float32),
    bary_v: inout(wp.float32),
) -> bool:
    """Out-argument form: writes ``face``, ``bary_u``, ``bary_v`` and gives True when a
    face closer than ``max_dist`` exists (the outputs are left alone otherwise)."""
    q = mesh_query_point_no_sign(id, point, max_dist)
    sign = 0.0  # not an output of the no-sign forms
    return _write_point(q, sign, face, bary_u, bary_v)


@func
def mesh_query_furthest_point_no_sign(
    id: wp.uint64, point: wp.vec3, min_dist: float
) -> MeshQueryPoint:
    """The point of mesh ``id`` furthest from ``point`` (a vertex), further than
    ``min_dist``; ``sign`` is 0."""
    return _point_answer_far(id, point, _furthest_face(id, point, min_dist))


@func
def mesh_query_furthest_point_no_sign(  # noqa: F811 - the out-argument form
    id: wp.uint64,
    point: wp.vec3,
    min_dist: float,
    face: inout(wp.int32),
    bary_u: inout(wp.float32),
    bary_v: inout(wp.float32),
) -> bool:
    """Out-argument form of ``mesh_query_furthest_point_no_sign``."""
    q = mesh_query_furthest_point_no_sign(id, point, min_dist)
    sign = 0.0  # not an output of the no-sign forms
    return _write_point(q, sign, face, bary_u, bary_v)


@func
def _point_answer_far(id: wp.uint64, point: wp.vec3, face: int) -> MeshQueryPoint:
    q = _point_found(False, 0.0, 0, wp.vec2(0.0))
    if face >= 0:
        rec = wp.object_record(id, MeshRecord)
        uv = furthest_point_to_triangle(
            _vertex(rec, face, 0), _vertex(rec, face, 1), _vertex(rec, face, 2), point
        )
        q = _point_found(True, 0.0, face, uv)
    return q


# -- rays ------------------------------------------------------------------------------


@wp.struct
class _FirstHit:
    """The nearest hit a ray search has found: its ``t``, its face and that face's
    position in the BVH's items (``slot``; -1 while nothing is found)."""

    t: wp.float32
    face: wp.int32
    slot: wp.int32


@func
def _ray_leaf(
    tri: wp.array(dtype=wp.vec3), items: wp.array(dtype=wp.int32), first: int, count: int,
    shear: RayShear, start: wp.vec3, best: _FirstHit,
) -> _FirstHit:  # fmt: skip
    """``best`` updated with the hits of the ``count`` faces of a leaf from
    ``items[first]`` (``tri``: the record's ``tri``, ``items`` the BVH's): a hit at
    ``t >= 0`` replaces it when nearer, or as near on a lower face."""
    hit = best
    for k in range(first, first + count):
        h = intersect_ray_triangle(shear, start, tri[k * 3], tri[k * 3 + 1], tri[k * 3 + 2])
        t = h[0]
        if t >= 0.0 and t <= hit.t:  # the face's number is loaded only here
            f = items[k]
            if t < hit.t or (hit.slot >= 0 and f < hit.face):
                hit.t = t
                hit.face = f
                hit.slot = k
    return hit


@func
def _wait_payload(
    firsts: wp.array(dtype=wp.int32), nexts: wp.array(dtype=wp.int32),
    keys: wp.array(dtype=wp.float32), count: int, first: int, next: int, key: float,
) -> int:  # fmt: skip
    """``_wait`` for a node carried as its payload (``first``, ``next``: see
    ``_ray_closest_slot``), so that taking it off the stack loads nothing. A full stack
    keeps its count and drops the node (which a walk that checked the tree's height
    never meets)."""
    if count < WALK_STACK:
        firsts[count] = first
        nexts[count] = next
        keys[count] = key
        return count + 1
    return count


@func
def _payload(nd: BvhNode, node: int) -> wp.vec2i:
    """The payload of node ``node`` (packed as ``nd``) for ``_ray_closest_slot``: a
    leaf's ``(first, count)``, an inner node's ``(left child, first)`` (its packed
    ``first`` names its right child: ``right_child``)."""
    if nd.first < 0:
        return wp.vec2i(node + 1, nd.first)
    return wp.vec2i(nd.first, nd.next)


@func
def _ray_closest_slot(id: wp.uint64, start: wp.vec3, dir: wp.vec3, max_t: float, root: int) -> int:
    """The position in the BVH's items of the face of the first hit along the ray at
    ``0 <= t < max_t`` (lowest face among equal ``t``), or -1.

    Front to back: at an inner node the child the ray enters first is visited next and
    the other waits on a small stack with its entry ``t``, dropped when a hit nearer
    than that is found meanwhile. A node is carried as its payload ``(a, b)`` (Warp's
    discipline): an inner node's left child and packed ``first`` (``b < 0``, which
    names the right child: the packed nodes are right-linked, ``kdsl.stdlib.bvh``), a
    leaf's faces ``[a, a + b)``; so a level loads both children's nodes at once, with
    no load waiting on another, and a waiting node is a payload and an entry ``t``, so
    taking it off the stack loads nothing (docs/performance.md, "Right-linked nodes,
    session 12"). The nodes, the leaves' corners and the face numbers are read through
    arrays made from their addresses (``packed_nodes``), whose strides are constants.
    A tree taller than the stack (``BvhRecord.height`` above ``WALK_STACK``: its walk
    could overflow the stack) takes a stackless pass over the whole range instead,
    bounded by the hit found so far; chosen before the walk, it leaves the stack walk
    without a fallback, which keeps the kernel within 64 registers on an H200 (4 blocks
    of 256 threads a multiprocessor; a fallback after an overflow, in the same loop,
    took 76). The answer never depends on the order."""
    rec = wp.object_record(id, MeshRecord)
    bvh = wp.object_record(rec.bvh, BvhRecord)
    nodes = packed_nodes(bvh)  # (the arrays by address: constant strides)
    tri = _tri_copy(rec)
    items = tree_items(bvh)
    shear = ray_shear(dir)
    inv = wp.vec3(safe_inverse(dir[0]), safe_inverse(dir[1]), safe_inverse(dir[2]))
    hit = _FirstHit()
    hit.t = max_t
    hit.face = -1
    hit.slot = -1
    span = _root_range(bvh, root)
    firsts = wp.ext.empty(WALK_STACK, dtype=wp.int32)  # pushed before popped: no zero fill
    nexts = wp.ext.empty(WALK_STACK, dtype=wp.int32)
    enters = wp.ext.empty(WALK_STACK, dtype=wp.float32)
    count = 0
    active = False  # a node is to be visited: its payload (a, b)
    a = 0
    b = 0
    if span[0] < span[1]:
        nd = nodes[span[0]]
        active = ray_box_enter(nd.lower, nd.upper, start, inv) <= hit.t
        p = _payload(nd, span[0])
        a = p[0]
        b = p[1]
    if bvh.height[0] > WALK_STACK:  # the stack could overflow: the stackless pass
        node = span[0]
        while node < span[1]:
            step = _next_ray_leaf(nodes, node, span[1], start, inv, hit.t)
            node = step[2]
            hit = _ray_leaf(tri, items, step[0], step[1], shear, start, hit)
        return hit.slot
    while active:
        # Down the nearer children to a leaf (or to where both children are missed: b
        # = 0), then the leaf's faces: "while-while", as the closest point.
        while b < 0:
            right = right_child(b)
            left_nd = nodes[a]
            right_nd = nodes[right]
            t_left = ray_box_enter(left_nd.lower, left_nd.upper, start, inv)
            t_right = ray_box_enter(right_nd.lower, right_nd.upper, start, inv)
            left_in = t_left <= hit.t  # (false for NaN: a missed box)
            right_in = t_right <= hit.t
            lp = _payload(left_nd, a)
            rp = _payload(right_nd, right)
            if right_in and (not left_in or t_right < t_left):  # the right one first
                if left_in:
                    count = _wait_payload(firsts, nexts, enters, count, lp[0], lp[1],
                                          t_left)  # fmt: skip
                a = rp[0]
                b = rp[1]
            elif left_in:
                if right_in:
                    count = _wait_payload(firsts, nexts, enters, count, rp[0], rp[1],
                                          t_right)  # fmt: skip
                a = lp[0]
                b = lp[1]
            else:  # both missed: no leaf to test
                b = 0
        hit = _ray_leaf(tri, items, a, b, shear, start, hit)
        # the nearest waiting node not beyond the hit found so far
        active = False
        while count > 0 and not active:
            count = count - 1
            if enters[count] <= hit.t:
                a = firsts[count]
                b = nexts[count]
                active = True
    return hit.slot


@wp.func_grad(_ray_closest_slot)
def _adj_ray_closest_slot(
    id: wp.uint64, start: wp.vec3, dir: wp.vec3, max_t: float, root: int, adj_ret: int
):  # fmt: skip
    """No gradient: the face found is piecewise constant in the ray. (The backward pass
    then replays the search whole rather than differentiating its loop, which reads a
    thread-local stack.)"""
    pass


@func
def _ray_closest(
    id: wp.uint64, start: wp.vec3, dir: wp.vec3, max_t: float, root: int
) -> MeshQueryRay:
    """The first hit along the ray at ``0 <= t < max_t`` (lowest face among equal ``t``).
    Its ``t``, barycentrics and sign are recomputed here, outside the search (the same
    test on the same corners, read from the leaves' copy, so the same values), so
    gradients reach ``start`` and ``dir`` through them; the normal is
    ``mesh_eval_face_normal``'s, from the same corners."""
    slot = _ray_closest_slot(id, start, dir, max_t, root)
    hit = MeshQueryRay()
    hit.result = False
    hit.sign = 0.0
    hit.face = 0
    hit.t = 0.0
    hit.u = 0.0
    hit.v = 0.0
    hit.normal = wp.vec3(0.0)
    if slot >= 0:
        rec = wp.object_record(id, MeshRecord)
        a = _corner(rec, slot, 0)
        b = _corner(rec, slot, 1)
        c = _corner(rec, slot, 2)
        h = intersect_ray_triangle(ray_shear(dir), start, a, b, c)
        hit.result = True
        hit.face = wp.object_record(rec.bvh, BvhRecord).items[slot]
        hit.t = h[0]
        hit.u = h[1]
        hit.v = h[2]
        hit.sign = h[3]
        hit.normal = wp.normalize(wp.cross(b - a, c - a))
    return hit


@func
def mesh_query_ray(
    id: wp.uint64, start: wp.vec3, dir: wp.vec3, max_t: float, root: int = -1
) -> MeshQueryRay:
    """The closest hit of the ray ``start + t * dir`` (``0 <= t < max_t``, ``t`` in
    multiples of ``dir``'s length) with mesh ``id``, searching the subtree ``root``
    (``mesh_get_group_root``; -1: the whole mesh). ``sign`` > 0 when the ray meets
    the face's front (counter-clockwise) side."""
    return _ray_closest(id, start, dir, max_t, root)


@func
def mesh_query_ray(  # noqa: F811 - the out-argument form
    id: wp.uint64,
    start: wp.vec3,
    dir: wp.vec3,
    max_t: float,
    t: inout(wp.float32),
    bary_u: inout(wp.float32),
    bary_v: inout(wp.float32),
    sign: inout(wp.float32),
    normal: inout(wp.vec3),
    face: inout(wp.int32),
    root: int = -1,
) -> bool:
    """Out-argument form of ``mesh_query_ray``: writes the outputs only on a hit."""
    h = _ray_closest(id, start, dir, max_t, root)
    if h.result:
        t = h.t  # noqa: F841 - in-out parameters: the caller sees them
        bary_u = h.u  # noqa: F841
        bary_v = h.v  # noqa: F841
        sign = h.sign  # noqa: F841
        normal = h.normal  # noqa: F841
        face = h.face  # noqa: F841
    return h.result


@func
def mesh_query_ray_anyhit(
    id: wp.uint64, start: wp.vec3, dir: wp.vec3, max_t: float, root: int = -1
) -> bool:
    """Whether the ray ``start + t * dir`` hits mesh ``id`` at some ``0 <= t < max_t``
    (stops at the first hit found)."""
    rec = wp.object_record(id, MeshRecord)
    bvh = wp.object_record(rec.bvh, BvhRecord)
    nodes = packed_nodes(bvh)  # (by address: constant strides)
    tri = _tri_copy(rec)
    shear = ray_shear(dir)
    inv = wp.vec3(safe_inverse(dir[0]), safe_inverse(dir[1]), safe_inverse(dir[2]))
    found = False
    span = _root_range(bvh, root)
    node = span[0]
    while node < span[1] and not found:
        step = _next_ray_leaf(nodes, node, span[1], start, inv, max_t)
        node = step[2]
        for k in range(step[0], step[0] + step[1]):
            h = intersect_ray_triangle(shear, start, tri[k * 3], tri[k * 3 + 1], tri[k * 3 + 2])
            if h[0] >= 0.0 and h[0] < max_t:
                found = True
    return found


@func
def _next_ray_leaf(
    nodes: wp.array(dtype=BvhNode), node: int, stop: int, start: wp.vec3, inv: wp.vec3,
    max_t: float,
) -> wp.vec3i:  # fmt: skip
    """``_next_near_leaf`` for a ray (``inv``: its direction's componentwise inverse) over
    a BVH's packed ``nodes``: the next leaf whose box the ray meets at some ``0 <= t <=
    max_t``."""
    while node < stop:
        nd = nodes[node]
        if ray_box_entry(nd.lower, nd.upper, start, inv, max_t):
            if nd.first >= 0:
                return wp.vec3i(nd.first, nd.next, node + 1)
            node = node + 1
        else:
            node = _skip(nd, node)
    return wp.vec3i(0, 0, stop)


@func
def mesh_query_ray_count_intersections(
    id: wp.uint64, start: wp.vec3, dir: wp.vec3, root: int = -1
) -> int:
    """The number of faces the ray ``start + t * dir`` (every ``t >= 0``) hits."""
    rec = wp.object_record(id, MeshRecord)
    bvh = wp.object_record(rec.bvh, BvhRecord)
    nodes = packed_nodes(bvh)  # (by address: constant strides)
    tri = _tri_copy(rec)
    shear = ray_shear(dir)
    inv = wp.vec3(safe_inverse(dir[0]), safe_inverse(dir[1]), safe_inverse(dir[2]))
    n = 0
    span = _root_range(bvh, root)
    node = span[0]
    while node < span[1]:
        step = _next_ray_leaf(nodes, node, span[1], start, inv, FLT_MAX)
        node = step[2]
        for k in range(step[0], step[0] + step[1]):
            h = intersect_ray_triangle(shear, start, tri[k * 3], tri[k * 3 + 1], tri[k * 3 + 2])
            if h[0] >= 0.0:
                n = n + 1
    return n


# -- inside/outside ----------------------------------------------------------------------


@func
def _sign_by_axis_rays(id: wp.uint64, point: wp.vec3) -> float:
    """Warp's default sign: -1 when at least two of the rays along +x, +y, +z first
    hit a face from behind (a miss votes outside), else 1."""
    votes = 0
    for axis in range(3):
        d = wp.vec3(0.0)
        d[axis] = 1.0
        h = _ray_closest(id, point, d, FLT_MAX, -1)
        if h.result and h.sign < 0.0:
            votes = votes + 1
    if votes >= 2:
        return -1.0
    return 1.0


@func
def _sign_by_parity(id: wp.uint64, point: wp.vec3, n_sample: int, scale: float) -> float:
    """Warp's parity sign: ``n_sample`` rays along ``(1, 1, 1)`` perturbed by a fixed
    random stream (seed 42); -1 when at least half cross an odd number of faces."""
    votes = 0
    state = rand_init(42)
    for _i in range(n_sample):
        d = wp.vec3(0.0)
        while wp.length_sq(d) < 1.0e-8:
            d = wp.vec3(1.0) + wp.vec3(
                randf(state, -scale, scale),
                randf(state, -scale, scale),
                randf(state, -scale, scale),
            )
        if mesh_query_ray_count_intersections(id, point, d) % 2 == 1:
            votes = votes + 1
    if votes * 2 >= n_sample:
        return -1.0
    return 1.0


@func
def _winding_number(id: wp.uint64, point: wp.vec3) -> float:
    """The exact generalized winding number of the mesh at ``point`` (the sum of its
    faces' solid angles over 4 pi), by brute force over every face."""
    rec = wp.object_record(id, MeshRecord)
    total = 0.0
    for f in range(rec.num_tris):
        total = total + triangle_solid_angle(
            _vertex(rec, f, 0), _vertex(rec, f, 1), _vertex(rec, f, 2), point
        )
    return total * INV_4PI


@func
def mesh_query_point(id: wp.uint64, point: wp.vec3, max_dist: float) -> MeshQueryPoint:
    """The closest point of mesh ``id`` to ``point`` (closer than ``max_dist``), with
    the sign by a majority vote of three axis rays (each votes inside when its first hit
    is a face's back; a miss votes outside). The sign ignores ``max_dist``."""
    face = _closest_face(id, point, max_dist)
    sign = 0.0
    if face >= 0:
        sign = _sign_by_axis_rays(id, point)
    return _point_answer(id, point, face, sign)


@func
def mesh_query_point(  # noqa: F811 - the out-argument form
    id: wp.uint64,
    point: wp.vec3,
    max_dist: float,
    inside: inout(wp.float32),
    face: inout(wp.int32),
    bary_u: inout(wp.float32),
    bary_v: inout(wp.float32),
) -> bool:
    """Out-argument form of ``mesh_query_point``: writes ``inside`` (< 0 inside),
    ``face``, ``bary_u``, ``bary_v`` when a face closer than ``max_dist`` exists."""
    q = mesh_query_point(id, point, max_dist)
    return _write_point(q, inside, face, bary_u, bary_v)


@func
def mesh_query_point_sign_parity(
    id: wp.uint64,
    point: wp.vec3,
    max_dist: float,
    n_sample: int = 1,
    perturbation_scale: float = 0.1,
) -> MeshQueryPoint:
    """The closest point, signed by ray parity: ``n_sample`` rays (a fixed, deterministic
    set) each count their crossings; inside when at least half count an odd number
    (``n_sample <= 0``: always inside, as Warp)."""
    face = _closest_face(id, point, max_dist)
    sign = 0.0
    if face >= 0:
        sign = _sign_by_parity(id, point, n_sample, perturbation_scale)
    return _point_answer(id, point, face, sign)


@func
def mesh_query_point_sign_parity(  # noqa: F811 - the out-argument form
    id: wp.uint64,
    point: wp.vec3,
    max_dist: float,
    inside: inout(wp.float32),
    face: inout(wp.int32),
    bary_u: inout(wp.float32),
    bary_v: inout(wp.float32),
    n_sample: int = 1,
    perturbation_scale: float = 0.1,
) -> bool:
    """Out-argument form of ``mesh_query_point_sign_parity``."""
    q = mesh_query_point_sign_parity(id, point, max_dist, n_sample, perturbation_scale)
    return _write_point(q, inside, face, bary_u, bary_v)


@func
def mesh_query_point_sign_winding_number(
    id: wp.uint64,
    point: wp.vec3,
    max_dist: float,
    accuracy: float = 2.0,
    threshold: float = 0.5,
) -> MeshQueryPoint:
    """The closest point, signed by the winding number: inside when it exceeds
    ``threshold``. kdsl computes the winding number exactly over every face (``accuracy``
    is accepted for Warp's signature and unused); on a mesh built without
    ``support_winding_number`` the sign is ``mesh_query_point``'s, as in Warp."""
    face = _closest_face(id, point, max_dist)
    sign = 0.0
    if face >= 0:
        rec = wp.object_record(id, MeshRecord)
        if rec.support_winding_number != 0:
            sign = 1.0
            if _winding_number(id, point) > threshold:
                sign = -1.0
        else:
            sign = _sign_by_axis_rays(id, point)
    return _point_answer(id, point, face, sign)


@func
def mesh_query_point_sign_winding_number(  # noqa: F811 - the out-argument form
    id: wp.uint64,
    point: wp.vec3,
    max_dist: float,
    inside: inout(wp.float32),
    face: inout(wp.int32),
    bary_u: inout(wp.float32),
    bary_v: inout(wp.float32),
    accuracy: float = 2.0,
    threshold: float = 0.5,
) -> bool:
    """Out-argument form of ``mesh_query_point_sign_winding_number``."""
    q = mesh_query_point_sign_winding_number(id, point, max_dist, accuracy, threshold)
    return _write_point(q, inside, face, bary_u, bary_v)


@func
def _corner_angle(e0: wp.vec3, e1: wp.vec3) -> float:
    return wp.acos(wp.clamp(wp.dot(wp.normalize(e0), wp.normalize(e1)), -1.0, 1.0))


@func
def _feature_weight(a: wp.vec3, b: wp.vec3, c: wp.vec3, q: wp.vec3, eps_sq: float) -> float:
    """The angle-weighted pseudo-normal weight of the face's feature nearest ``q``: its
    corner angle at a vertex, pi on an edge, 2 pi inside the face (Warp's rule)."""
    e0 = b - a
    e1 = c - a
    e2 = c - b
    qa = q - a
    qb = q - b
    if wp.length_sq(qa) < eps_sq:
        return _corner_angle(e0, e1)
    if wp.length_sq(qb) < eps_sq:
        return _corner_angle(e2, -e0)
    if wp.length_sq(q - c) < eps_sq:
        return _corner_angle(-e1, -e2)
    n0 = wp.dot(e0, e0)
    n1 = wp.dot(e1, e1)
    n2 = wp.dot(e2, e2)
    d0 = wp.dot(e0, qa)
    d2 = wp.dot(e2, qb)
    d1 = wp.dot(e1, qa)
    on_edge = (
        wp.length_sq(qa) * n0 - d0 * d0 < eps_sq * n0
        or wp.length_sq(qb) * n2 - d2 * d2 < eps_sq * n2
        or wp.length_sq(qa) * n1 - d1 * d1 < eps_sq * n1
    )
    if on_edge:
        return 3.14159265359
    return 2.0 * 3.14159265359


@func
def mesh_query_point_sign_normal(
    id: wp.uint64, point: wp.vec3, max_dist: float, epsilon: float = 1.0e-3
) -> MeshQueryPoint:
    """The closest point, signed by the angle-weighted pseudo-normal of the closest
    feature (faces within ``epsilon`` times the mean edge length of the closest distance
    count as touching it): fast, for watertight, non-self-intersecting meshes."""
    rec = wp.object_record(id, MeshRecord)
    bvh = wp.object_record(rec.bvh, BvhRecord)
    eps = 0.0
    if rec.num_tris > 0:  # epsilon times the mean edge length
        eps = rec.edge_length_sum[0] / float(3 * rec.num_tris) * epsilon
    best = max_dist
    best_face = -1
    normal = wp.vec3(0.0)
    span = _root_range(bvh, -1)
    node = span[0]
    while node < span[1]:
        reach = best + eps
        step = _next_near_leaf(bvh.nodes, node, span[1], point, reach * reach)
        node = step[2]
        for k in range(step[0], step[0] + step[1]):
            a = _corner(rec, k, 0)
            b = _corner(rec, k, 1)
            c = _corner(rec, k, 2)
            if not is_sliver(a, b, c):
                q = _face_point(a, b, c, point, False)
                d = wp.length(q - point)
                if d < best + eps:
                    f = bvh.items[k]
                    n = wp.normalize(wp.cross(b - a, c - a))
                    w = _feature_weight(a, b, c, q, eps * eps)
                    if d > best - eps:  # as close as the best: add its normal
                        normal = normal + w * n
                        if d < best or (d == best and best_face >= 0 and f < best_face):
                            best = d
                            best_face = f
                    else:  # clearly closer: start again from this face
                        best = d
                        best_face = f
                        normal = w * n
    if not (best < max_dist):
        best_face = -1
    sign = 0.0
    if best_face >= 0:
        uv = _face_bary(rec, best_face, point)
        q = _point_on_face(rec, best_face, uv[0], uv[1])
        sign = -1.0
        if wp.dot(normal, point - q) > 0.0:
            sign = 1.0
    return _point_answer(id, point, best_face, sign)


@func
def mesh_query_point_sign_normal(  # noqa: F811 - the out-argument form
    id: wp.uint64,
    point: wp.vec3,
    max_dist: float,
    inside: inout(wp.float32),
    face: inout(wp.int32),
    bary_u: inout(wp.float32),
    bary_v: inout(wp.float32),
    epsilon: float = 1.0e-3,
) -> bool:
    """Out-argument form of ``mesh_query_point_sign_normal``."""
    q = mesh_query_point_sign_normal(id, point, max_dist, epsilon)
    return _write_point(q, inside, face, bary_u, bary_v)


# -- box and sphere queries --------------------------------------------------------------


@func
def mesh_query_aabb(id: wp.uint64, low: wp.vec3, high: wp.vec3) -> MeshQueryAABB:
    """A query for the faces whose bounding box overlaps ``[low, high]`` (broad phase
    only); advance it with ``mesh_query_next``."""
    q = MeshQueryAABB()
    q.mesh = id
    q.kind = AABB
    q.center = low
    q.radius = 0.0
    q.bvh = bvh_query_aabb(wp.object_record(id, MeshRecord).bvh, low, high)
    return q


@func
def mesh_query_sphere(id: wp.uint64, center: wp.vec3, radius: float) -> MeshQueryAABB:
    """A query for the faces within ``radius`` of ``center`` (touching counts; a negative
    radius is 0; a zero-area face is tested as its longest edge); advance it with
    ``mesh_query_next``."""
    r = wp.max(radius, 0.0)
    q = MeshQueryAABB()
    q.mesh = id
    q.kind = SPHERE
    q.center = center
    q.radius = r
    q.bvh = bvh_query_sphere(wp.object_record(id, MeshRecord).bvh, center, r)
    return q


@func
def _face_within(rec: MeshRecord, face: int, center: wp.vec3, radius: float) -> bool:
    a = _vertex(rec, face, 0)
    b = _vertex(rec, face, 1)
    c = _vertex(rec, face, 2)
    ab = b - a
    ac = c - a
    n = wp.cross(ab, ac)
    q = wp.vec3(0.0)
    if wp.dot(n, n) == 0.0:  # no area: the longest edge stands for the face
        bc = c - b
        lab = wp.dot(ab, ab)
        lac = wp.dot(ac, ac)
        lbc = wp.dot(bc, bc)
        p0 = b
        p1 = c
        len2 = lbc
        if lab >= lac and lab >= lbc:
            p0 = a
            p1 = b
            len2 = lab
        elif lac >= lbc:
            p0 = a
            p1 = c
            len2 = lac
        t = 0.0
        if len2 > 0.0:
            t = wp.clamp(wp.dot(center - p0, p1 - p0) / len2, 0.0, 1.0)
        q = p0 + t * (p1 - p0)
    else:
        uv = closest_point_to_triangle(a, b, c, center)
        q = a * uv[0] + b * uv[1] + c * (1.0 - uv[0] - uv[1])
    return wp.length_sq(q - center) <= radius * radius


@func
def mesh_query_next(query: inout(MeshQueryAABB), index: inout(wp.int32)) -> bool:
    """Advance a ``mesh_query_aabb`` or ``mesh_query_sphere`` query: writes the next
    matching face to ``index`` and gives True, or gives False (``index`` unchanged)."""
    rec = wp.object_record(query.mesh, MeshRecord)
    bq = query.bvh
    face = 0
    found = False
    while not found and bvh_query_next(bq, face):
        if query.kind == AABB or _face_within(rec, face, query.center, query.radius):
            found = True
    query.bvh = bq
    if found:
        index = face  # noqa: F841 - in-out parameter: the caller sees it
    return found


@func
def mesh_query_aabb_next(query: inout(MeshQueryAABB), index: inout(wp.int32)) -> bool:
    """``mesh_query_next`` under its older name."""
    return mesh_query_next(query, index)


# -- evaluation and access ------------------------------------------------------------------


@func
def mesh_eval_position(id: wp.uint64, face: int, bary_u: float, bary_v: float) -> wp.vec3:
    """``u * v0 + v * v1 + (1 - u - v) * v2`` over face ``face``'s vertex positions."""
    rec = wp.object_record(id, MeshRecord)
    return _point_on_face(rec, face, bary_u, bary_v)


@func
def mesh_eval_velocity(id: wp.uint64, face: int, bary_u: float, bary_v: float) -> wp.vec3:
    """The velocities of face ``face``'s vertices interpolated as ``mesh_eval_position``
    does; zero for a mesh without velocities."""
    rec = wp.object_record(id, MeshRecord)
    if rec.velocities.shape[0] == 0:
        return wp.vec3(0.0)
    a = rec.velocities[rec.indices[face * 3]]
    b = rec.velocities[rec.indices[face * 3 + 1]]
    c = rec.velocities[rec.indices[face * 3 + 2]]
    return a * bary_u + b * bary_v + c * (1.0 - bary_u - bary_v)


@func
def mesh_eval_face_normal(id: wp.uint64, face: int) -> wp.vec3:
    """The unit normal of face ``face``, oriented by its winding (zero for a face of no
    area)."""
    rec = wp.object_record(id, MeshRecord)
    a = _vertex(rec, face, 0)
    return wp.normalize(wp.cross(_vertex(rec, face, 1) - a, _vertex(rec, face, 2) - a))


@func
def mesh_get(id: wp.uint64) -> MeshRecord:
    """The mesh's record: its ``points``, ``velocities`` and ``indices`` arrays."""
    return wp.object_record(id, MeshRecord)


@func
def mesh_get_point(id: wp.uint64, index: int) -> wp.vec3:
    """The position of face-vertex ``index`` (``points[indices[index]]``)."""
    rec = wp.object_record(id, MeshRecord)
    return rec.points[rec.indices[index]]


@func
def mesh_get_velocity(id: wp.uint64, index: int) -> wp.vec3:
    """The velocity of face-vertex ``index`` (zero for a mesh without velocities)."""
    rec = wp.object_record(id, MeshRecord)
    if rec.velocities.shape[0] == 0:
        return wp.vec3(0.0)
    return rec.velocities[rec.indices[index]]


@func
def mesh_get_index(id: wp.uint64, index: int) -> int:
    """The point index of face-vertex ``index`` (``indices[index]``)."""
    return wp.object_record(id, MeshRecord).indices[index]


@func
def mesh_get_bvh(id: wp.uint64) -> wp.uint64:
    """The id of the mesh's BVH over its faces, for the ``bvh_query_*`` functions (their
    items are face indices)."""
    return wp.object_record(id, MeshRecord).bvh


@func
def mesh_get_group_root(id: wp.uint64, group: int) -> int:
    """The root node of group ``group``'s faces (pass it as a ray query's ``root``), or
    -1 (the whole mesh) for a group with no faces."""
    return bvh_get_group_root(wp.object_record(id, MeshRecord).bvh, group)
