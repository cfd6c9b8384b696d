"""kdsl standard library: the closest- and furthest-point walks over a mesh's 4-wide
tree, in kdsl.

A mesh on a device that keeps one (``kdsl.geometry.wide_tree``; the CPU) has, beside
its binary BVH, the same tree collapsed to four children a node, in the layout
Embree's BVH4 uses for SIMD: a ``WideNode`` holds its four children's boxes as six
vec4 (the four lower x, the four lower y, ...), so the four box distances of a node
visit are one pass of vector instructions, and a leaf (``WideLeaf``) holds up to four
faces as nine vec4 (the four faces' corner a x, ...), tested together without
branches. docs/geometry.md ("Wide tree") describes the layout and its upkeep.

The walk visits the nearer children first (each child's place on a stack of
``WIDE_STACK`` entries is its rank among the four by distance, pushed far to near) and
tests a leaf when it comes off the stack, at one site. A node visit first prefetches
its four children (``kd.prefetch``), so that their cache misses overlap instead of
coming one per step (1.3x in an A/B on the benchmark's 200k-face mesh). It answers as the binary walk
(``kdsl.stdlib.mesh._closest_face``): the lowest face index among the faces at the
smallest distance below ``max_dist``, slivers left out (their lanes carry face -1), a
NaN point finds nothing; each face's distance is computed by the same float32
operations in the same order as ``closest_point_to_triangle`` and the binary leaf
test, so the same face wins. (Both walks drop a box only when its computed distance
exceeds the best face's; the wide walk tests a subset of the binary tree's boxes, so
the two could differ only for a face whose computed distance rounds below its own
box's, on the box's boundary: no test has met one.) A tree too deep for the stack (or a leaf of more than
four faces) gives ``WIDE_OVERFLOW``: the caller then walks the binary tree. The
furthest point (``wide_furthest_face``) is the same walk turned around.

Only the backends that take these walks compile them (``target_has_wide_tree()``,
``kd.target_has``: a constant per backend, true on cpu and interp): on cuda the walks
reduce to ``return WIDE_OVERFLOW`` and the kernel keeps the binary walk alone (with the
wide walk compiled in but never run, an H200's closest-point kernel took 57.7 ms
instead of 33.9).
"""

import kdsl as wp
from kdsl.frontend.builtins_prefetch import PREFETCH as prefetch
from kdsl.frontend.builtins_target import TARGET_HAS_WIDE_TREE as target_has_wide_tree
from kdsl.frontend.inout import inout
from kdsl.frontend.kernel import func
from kdsl.stdlib.mesh_primitives import box_distance_sq, box_furthest_distance_sq

__kdsl_group__ = "geometry"

#: Helpers of kdsl.stdlib.mesh, not kernel builtins of their own.
__all__: list[str] = []

#: Entries of the wide walk's stack: a node visit pushes up to four, so at most three
#: more than it pops; 64 covers a wide tree 20 levels deep (a binary tree of about 40).
WIDE_STACK = 64
#: What ``wide_closest_face`` gives when it cannot answer (stack full, or a tree the
#: collapse refused): walk the binary tree instead.
WIDE_OVERFLOW = -2


@wp.struct(align=16)
class WideNode:
    """A node of the 4-wide tree (128 bytes): its four children's boxes in SoA form
    (``lo_x[i]`` is child ``i``'s lower x; an empty slot's box is NaN, which no
    distance test passes), ``child[i]`` (>= 0: a wide node; < 0: the leaf
    ``-child[i] - 1``) and ``src[i]``, the binary tree's node whose box child ``i``
    has (-1: empty), which the refit copies."""

    lo_x: wp.vec4
    lo_y: wp.vec4
    lo_z: wp.vec4
    hi_x: wp.vec4
    hi_y: wp.vec4
    hi_z: wp.vec4
    child: wp.vec4i
    src: wp.vec4i


@wp.struct(align=16)
class WideLeaf:
    """A leaf of the 4-wide tree (160 bytes): up to four faces' corners in SoA form
    (``ax[i]`` is face ``i``'s first corner's x) and their numbers (``face[i]``: -1
    for an empty lane or a sliver, which point queries leave out)."""

    ax: wp.vec4
    ay: wp.vec4
    az: wp.vec4
    bx: wp.vec4
    by: wp.vec4
    bz: wp.vec4
    cx: wp.vec4
    cy: wp.vec4
    cz: wp.vec4
    face: wp.vec4i


@wp.struct
class WideRecord:
    """The record of a mesh's 4-wide tree: its nodes (node 0 is the root; none for a
    mesh without faces) and leaves; ``fallback`` != 0 when the collapse refused the
    binary tree (a leaf of more than four faces): the walk then defers to the binary
    one."""

    tag: wp.uint64
    nodes: wp.array(dtype=WideNode)
    leaves: wp.array(dtype=WideLeaf)
    fallback: wp.int32


@func
def wide_box_distances(nd: WideNode, p: wp.vec3) -> wp.vec4:
    """The squared distances from ``p`` to the node's four child boxes (NaN for an
    empty slot or a NaN ``p``)."""
    d = wp.vec4(0.0)
    for i in range(wp.static(4)):
        d[i] = box_distance_sq(
            wp.vec3(nd.lo_x[i], nd.lo_y[i], nd.lo_z[i]),
            wp.vec3(nd.hi_x[i], nd.hi_y[i], nd.hi_z[i]), p,
        )  # fmt: skip
    return d


@func
def _lane_distance(
    ax: float, ay: float, az: float, bx: float, by: float, bz: float, cx: float, cy: float,
    cz: float, p: wp.vec3,
) -> float:  # fmt: skip
    """The squared distance from ``p`` to triangle ``(a, b, c)``, branch-free: every
    region of ``closest_point_to_triangle`` is computed and the first that holds (in
    its order) chosen by selects, each with that function's operations in its order,
    then ``length_sq(a u + b v + c (1 - u - v) - p)`` as the binary leaf test."""
    a = wp.vec3(ax, ay, az)
    b = wp.vec3(bx, by, bz)
    c = wp.vec3(cx, cy, cz)
    ab = b - a
    ac = c - a
    ap = p - a
    d1 = wp.dot(ab, ap)
    d2 = wp.dot(ac, ap)
    bp = p - b
    d3 = wp.dot(ab, bp)
    d4 = wp.dot(ac, bp)
    cp = p - c
    d5 = wp.dot(ab, cp)
    d6 = wp.dot(ac, cp)
    vc = d1 * d4 - d3 * d2
    vb = d5 * d2 - d1 * d6
    va = d3 * d6 - d5 * d4
    denom = 1.0 / (va + vb + vc)  # inside the face
    v_in = vb * denom
    w_in = vc * denom
    u = 1.0 - v_in - w_in
    v = v_in
    w_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))  # edge bc
    on = (va <= 0.0) & ((d4 - d3) >= 0.0) & ((d5 - d6) >= 0.0)
    u = 0.0 if on else u
    v = 1.0 - w_bc if on else v
    w_ac = d2 / (d2 - d6)  # edge ac
    on = (vb <= 0.0) & (d2 >= 0.0) & (d6 <= 0.0)
    u = 1.0 - w_ac if on else u
    v = 0.0 if on else v
    on = (d6 >= 0.0) & (d5 <= d6)  # vertex c
    u = 0.0 if on else u
    v = 0.0 if on else v
    v_ab = d1 / (d1 - d3)  # edge ab
    on = (vc <= 0.0) & (d1 >= 0.0) & (d3 <= 0.0)
    u = 1.0 - v_ab if on else u
    v = v_ab if on else v
    on = (d3 >= 0.0) & (d4 <= d3)  # vertex b
    u = 0.0 if on else u
    v = 1.0 if on else v
    on = (d1 <= 0.0) & (d2 <= 0.0)  # vertex a
    u = 1.0 if on else u
    v = 0.0 if on else v
    q = a * u + b * v + c * (1.0 - u - v)
    return wp.length_sq(q - p)


@func
def _wide_leaf(lf: WideLeaf, p: wp.vec3, best_d: inout(wp.float32), best_f: inout(wp.int32)):
    """``best_d``/``best_f`` updated with the leaf's faces: a face replaces the best when
    strictly closer, or as close with a lower index (an empty or sliver lane never)."""
    d = wp.vec4(0.0)
    for i in range(wp.static(4)):
        d[i] = _lane_distance(
            lf.ax[i], lf.ay[i], lf.az[i], lf.bx[i], lf.by[i], lf.bz[i], lf.cx[i], lf.cy[i],
            lf.cz[i], p,
        )  # fmt: skip
        d[i] = d[i] if lf.face[i] >= 0 else wp.nan
    near = (d[0] <= best_d) | (d[1] <= best_d) | (d[2] <= best_d) | (d[3] <= best_d)
    if near:  # (rare once a close face is known: one test for the four lanes)
        for i in range(wp.static(4)):
            f = lf.face[i]
            if d[i] < best_d or (d[i] == best_d and best_f >= 0 and f < best_f):
                best_d = d[i]
                best_f = f


@func
def _push_children(
    refs: wp.array(dtype=wp.int32), keys: wp.array(dtype=wp.float32), count: int, d: wp.vec4,
    child: wp.vec4i, best_d: float,
) -> int:  # fmt: skip
    """Push the children within ``best_d`` (their distances ``d``) far to near onto the
    stack of ``count`` entries (room for four is left); the new count.

    Each child's place is its rank among them (how many are nearer, ties in lane
    order), counted with comparisons of all four lanes at once; a child beyond
    ``best_d`` (NaN key, which compares false) is written to the spare last slot."""
    k = wp.vec4(0.0)
    hits = 0
    for i in range(wp.static(4)):
        k[i] = d[i] if d[i] <= best_d else wp.nan
        hits = hits + int(d[i] <= best_d)
    top = count + hits - 1
    for i in range(wp.static(4)):
        rank = 0
        for j in range(wp.static(4)):
            if j < i:
                rank = rank + int(k[j] <= k[i])
            elif j > i:
                rank = rank + int(k[j] < k[i])
        at = top - rank if k[i] == k[i] else WIDE_STACK
        refs[at] = child[i]
        keys[at] = k[i]
    return count + hits


@func
def _prefetch_children(w: WideRecord, child: wp.vec4i):
    """Prefetch the node's four children (``kd.prefetch``), whether they will be pushed
    or not: their loads, one after another as they come off the stack, then find them
    in the cache (the nearest comes off next, the others after its subtree). Testing
    each child's distance first measured slower; issued after the distances, the hints
    made LLVM split the four box distances into two-lane vectors. An empty slot names
    leaf 0, a harmless hint."""
    for i in range(wp.static(4)):
        c = child[i]
        if c < 0:
            prefetch(w.leaves, -c - 1)
        else:
            prefetch(w.nodes, c)


@func
def _wide_leaf_far(lf: WideLeaf, p: wp.vec3, best_d: inout(wp.float32), best_f: inout(wp.int32)):
    """``_wide_leaf`` for the furthest point: a face's distance is its furthest
    vertex's (the binary walk's ``furthest_point_to_triangle``, whose vertex is exactly
    ``a``, ``b`` or ``c``: the same float32 value), and a face replaces the best when
    strictly further, or as far with a lower index."""
    d = wp.vec4(0.0)
    for i in range(wp.static(4)):
        da = wp.length_sq(p - wp.vec3(lf.ax[i], lf.ay[i], lf.az[i]))
        db = wp.length_sq(p - wp.vec3(lf.bx[i], lf.by[i], lf.bz[i]))
        dc = wp.length_sq(p - wp.vec3(lf.cx[i], lf.cy[i], lf.cz[i]))
        m = db if db > dc else dc
        m = da if (da > db) & (da > dc) else m
        d[i] = m if lf.face[i] >= 0 else wp.nan
    far = (d[0] >= best_d) | (d[1] >= best_d) | (d[2] >= best_d) | (d[3] >= best_d)
    if far:
        for i in range(wp.static(4)):
            f = lf.face[i]
            if d[i] > best_d or (d[i] == best_d and best_f >= 0 and f < best_f):
                best_d = d[i]
                best_f = f


@func
def _far_box_distances(nd: WideNode, p: wp.vec3) -> wp.vec4:
    """The negated squared distances from ``p`` to the furthest corners of the node's
    four child boxes (NaN for an empty slot)."""
    d = wp.vec4(0.0)
    for i in range(wp.static(4)):
        d[i] = -box_furthest_distance_sq(
            wp.vec3(nd.lo_x[i], nd.lo_y[i], nd.lo_z[i]),
            wp.vec3(nd.hi_x[i], nd.hi_y[i], nd.hi_z[i]), p,
        )  # fmt: skip
        d[i] = d[i] if nd.src[i] >= 0 else wp.nan  # (a NaN box's furthest corner is not)
    return d


@func
def _wide_walk(id: wp.uint64, point: wp.vec3, dist: float, far: bool) -> int:
    """``wide_closest_face`` (``far`` False) or ``wide_furthest_face`` (True; ``far`` is
    a literal at both calls, so each inlined copy keeps one path). The furthest walk
    runs on negated distances: a box's key is minus its furthest corner's distance, the
    bound minus the furthest face's, so both walks drop an entry whose key exceeds the
    bound and take the smallest key first."""
    if not target_has_wide_tree():  # (a constant: the backend compiles one path)
        return WIDE_OVERFLOW
    w = wp.object_record(id, WideRecord)
    if w.fallback != 0:
        return WIDE_OVERFLOW
    best_d = dist * dist
    sign = 1.0
    if far:
        sign = -1.0
        if dist < 0.0:
            best_d = -1.0
    best_f = -1
    # Written before read (no zero fill); the last entry takes the children not pushed.
    refs = wp.ext.empty(WIDE_STACK + 1, dtype=wp.int32)
    keys = wp.ext.empty(WIDE_STACK + 1, dtype=wp.float32)
    count = 0
    if w.nodes.shape[0] > 0:
        refs[0] = 0  # the root: its children are tested against the bound
        keys[0] = -wp.inf
        count = 1
    while count > 0:
        count = count - 1
        ref = refs[count]
        bound = sign * best_d
        if keys[count] <= bound:
            if ref < 0:
                if far:
                    _wide_leaf_far(w.leaves[-ref - 1], point, best_d, best_f)
                else:
                    _wide_leaf(w.leaves[-ref - 1], point, best_d, best_f)
            elif count > WIDE_STACK - 4:
                return WIDE_OVERFLOW
            else:
                nd = w.nodes[ref]
                _prefetch_children(w, nd.child)  # (before the distances: more lead)
                d = wp.vec4(0.0)
                if far:
                    d = _far_box_distances(nd, point)
                else:
                    d = wide_box_distances(nd, point)
                # (One test of the four lanes: it also lets LLVM compute the four
                # distances as one vector, its SLP vectorizer's seed.)
                near = (d[0] <= bound) | (d[1] <= bound) | (d[2] <= bound) | (d[3] <= bound)
                if near:
                    count = _push_children(refs, keys, count, d, nd.child, bound)
    return best_f


@func
def wide_closest_face(id: wp.uint64, point: wp.vec3, max_dist: float) -> int:
    """The face closest to ``point`` at a distance strictly below ``max_dist`` (lowest
    index among ties; slivers left out), or -1, by the 4-wide tree ``id``
    (``WideRecord``); ``WIDE_OVERFLOW`` when the walk cannot answer (see the module
    docstring).

    Each step takes an entry off the stack, dropped when its box lies beyond the
    closest distance found meanwhile: a leaf is tested, a node's four child boxes are
    measured, the children within that distance sorted by it and pushed far to near,
    so the nearest comes off next."""
    return _wide_walk(id, point, max_dist, False)


@func
def wide_furthest_face(id: wp.uint64, point: wp.vec3, min_dist: float) -> int:
    """The face whose furthest vertex from ``point`` is furthest, strictly beyond
    ``min_dist`` (lowest index among ties; slivers left out), or -1, by the 4-wide
    tree ``id``; ``WIDE_OVERFLOW`` when the walk cannot answer.

    ``wide_closest_face`` turned around: an entry is dropped when its box's furthest
    corner lies nearer than the furthest face found, and the children are pushed near
    to far, so the furthest comes off next."""
    return _wide_walk(id, point, min_dist, True)
