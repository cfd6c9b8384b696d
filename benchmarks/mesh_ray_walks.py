"""Variants of the mesh ray walks (``mesh_query_ray``'s search, the any hit, the counted
hits), compiled side by side as user ``@func`` code, for A/B timing against the standard
library and Warp.

    python benchmarks/mesh_ray_walks.py [--tris 200000] [--rays 1000000] [--reps 20]
        [--device cuda:0] [--variants prefetch,payload,any_lib,any_stack] [--no-warp]
        [--json PATH]

Each variant is a kernel over one ray per thread on the bumpy cube-sphere of
``bench_geometry_mesh.workload`` (``mesh_query_ray(mesh, start, dir, 1e6)`` and its
kin). ``lib`` (always run) calls the library's ``mesh_query_ray``. The variants
(``VARIANTS``), by family:

- closest hit (compared with ``lib``: faces and ``t`` exactly):
  - ``prefetch``: session 11's library search (``8318df0``): the packed nodes named only
    the left child, so an inner node was carried with its right child read from the
    BVH's ``skip`` array a level ahead (``skip[n + 1]``), a waiting node with its
    ``first``, ``next`` and right child; with the stackless fallback;
  - ``onesite``: the first walk of session 12 (``acb138b``): Warp's discipline on the
    right-linked nodes (an inner node's packed ``first`` is ``-1 - right``, so both
    children load at once, and a stack entry is a payload and an entry ``t``) on the
    records' arrays, the stackless pass taken after an overflow in the same loop;
  - ``payload``: the same without the stackless pass (-2 where the stack would
    overflow);
  - ``addr``: ``onesite`` with its arrays (nodes, the leaves' corners, the face
    numbers) read through the records' addresses (``packed_nodes``: constant strides,
    no stride in registers) instead of the records' arrays;
  - ``split``: ``addr`` with the stackless pass chosen before the walk (for a tree that
    may overflow the stack), so the stack walk has no fallback: the library's walk
    since ``lib`` reads the tree's height (here a record's value that is never
    negative stands for it); ``split_rec``: the same on the records' arrays;
  - ``*_r64``: the kernel compiled with ``cuda_max_registers=64``;
- any hit (``any_*``, compared with ``any_lib``, the library's
  ``mesh_query_ray_anyhit``, timed beside Warp's any-hit kernel ``warp_any``):
  ``any_stack`` walks the right-linked nodes with a stack of payloads (both children
  loaded at once, the left one first), ``any_near`` the same entering the nearer child
  first; neither has a fallback (-2 on overflow); ``any_addr`` / ``any_rec``: the
  library's stackless walk through the records' addresses / on the records' arrays;
- counted hits (``count_*``, compared with ``count_lib``,
  ``mesh_query_ray_count_intersections``, beside Warp's ``warp_count``): ``count_stack``
  as ``any_stack`` without the early exit; ``count_stack_addr`` the same through the
  records' addresses; ``count_rec`` the library's stackless count on the records'
  arrays;
- closest points (``point_*``, the workload's query points, ``mesh_query_point_no_sign``
  at ``MAX_DIST``; faces and ``u`` compared with ``point_lib``, the library's, beside
  Warp's ``warp_point``): ``point_skip``, the library's binary walk before session 12,
  where the far child's load waited for the near child's (its ``skip``);
  ``point_link``, the walk of ``364b2f8`` (the far child from the node's link);
  ``point_addr``, that walk through the records' addresses.

Session 11 (docs/performance.md, "Mesh rays on the GPU, session 11") also ran the
session-10 search filled and not (``old_lib``, ``git show
f8cbe2b:benchmarks/mesh_ray_walks.py``) and copies without the stackless fallback, an
unpadded slab test, kept pops, global loads and the left child loaded a level ahead
(``git show 6850bcd:benchmarks/mesh_ray_walks.py``).
Every closest-hit kernel but ``lib`` recomputes the hit after the search as the library
does (so the times compare searches). Times are the minimum over ``--reps`` launches
after a warm-up. Answers are checked within each family; the library's hit/miss must
agree with Warp's on all but ``RAY_DISAGREEMENT`` of the rays (any hits and counts too;
closest points: found or not, as faces may tie).
The table prints ms per launch and the ratio to Warp's time for the family (> 1:
faster than Warp).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

import kdsl as wp
from kdsl.stdlib.bvh import BvhNode, BvhRecord, packed_nodes, tree_items
from kdsl.stdlib.mesh import MeshRecord
from kdsl.stdlib.mesh_primitives import (
    RayShear,
    box_distance_sq,
    closest_point_to_triangle,
    intersect_ray_triangle,
    is_sliver,
    ray_box_enter,
    ray_shear,
    safe_inverse,
)

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_geometry_mesh import MAX_DIST, MAX_T, RAY_DISAGREEMENT, mesh_kernels, workload

STACK = 32
#: The variants: name -> ``variant_kernel``'s keywords (its defaults: the library's walk).
VARIANTS = {
    "prefetch": {"walk": "prefetch"},
    "onesite": {"walk": "onesite"},
    "addr": {"walk": "addr"},
    "split": {"walk": "split"},
    "split_rec": {"walk": "split_rec"},
    "payload": {"walk": "payload"},
    "lib_r64": {"walk": "lib", "regs": 64},
    "any_lib": {"walk": "any_lib"},
    "any_stack": {"walk": "any_stack"},
    "any_near": {"walk": "any_near"},
    "count_lib": {"walk": "count_lib"},
    "count_stack": {"walk": "count_stack"},
    "any_addr": {"walk": "any_addr"},
    "any_rec": {"walk": "any_rec"},
    "count_rec": {"walk": "count_rec"},
    "count_stack_addr": {"walk": "count_stack_addr"},
    "point_lib": {"walk": "point_lib"},
    "point_skip": {"walk": "point_skip"},
    "point_link": {"walk": "point_link"},
    "point_addr": {"walk": "point_addr"},
}
#: Each family's reference variant (answers compared with it) and Warp's row.
FAMILIES = {"ray": ("lib", "warp"), "any": ("any_lib", "warp_any"),
            "count": ("count_lib", "warp_count"), "point": ("point_lib", "warp_point")}  # fmt: skip


def family(name: str) -> str:
    """The family of variant ``name``: "any", "count", "point" or "ray" (closest hit)."""
    for f in ("any", "count", "point"):
        if name.startswith(f + "_"):
            return f
    return "ray"


@wp.struct
class Hit:
    t: wp.float32
    face: wp.int32
    slot: wp.int32


@wp.func
def no_hit(max_t: float) -> Hit:
    """A search's start: no face, bounded by ``max_t``."""
    hit = Hit()
    hit.t = max_t
    hit.face = -1
    hit.slot = -1
    return hit


@wp.func
def inverse(dir: wp.vec3) -> wp.vec3:
    """The ray direction's componentwise inverse for the slab tests (as the library's)."""
    return wp.vec3(safe_inverse(dir[0]), safe_inverse(dir[1]), safe_inverse(dir[2]))


@wp.func
def leaf_hits(tri: wp.array(dtype=wp.vec3), items: wp.array(dtype=wp.int32), first: int,
              count: int, shear: RayShear, start: wp.vec3, best: Hit) -> Hit:  # fmt: skip
    """The library's leaf test of the closest hit (corners in ``tri``, a mesh's copy;
    face numbers in ``items``, the BVH's item order)."""
    hit = best
    for k in range(first, first + count):
        h = intersect_ray_triangle(shear, start, tri[k * 3], tri[k * 3 + 1], tri[k * 3 + 2])
        t = h[0]
        if t >= 0.0 and t <= hit.t:
            f = items[k]
            if t < hit.t or (hit.slot >= 0 and f < hit.face):
                hit.t = t
                hit.face = f
                hit.slot = k
    return hit


@wp.func
def leaf_count(tri: wp.array(dtype=wp.vec3), first: int, count: int, shear: RayShear,
               start: wp.vec3, max_t: float) -> int:  # fmt: skip
    """The faces of a leaf (corners in ``tri``, a mesh's ``tri``) the ray hits at ``0 <=
    t < max_t``."""
    n = 0
    for k in range(first, first + count):
        h = intersect_ray_triangle(shear, start, tri[k * 3], tri[k * 3 + 1], tri[k * 3 + 2])
        if h[0] >= 0.0 and h[0] < max_t:
            n = n + 1
    return n


@wp.func
def root_range(bvh: BvhRecord, root: int) -> wp.vec2i:
    start = root
    if start < 0:
        start = bvh.root
    if start < 0:
        return wp.vec2i(0, 0)
    return wp.vec2i(start, bvh.skip[start])


@wp.func
def skip_of(nd: BvhNode, node: int) -> int:
    if nd.first < 0:
        return nd.next
    return node + 1


@wp.func
def next_ray_leaf(nodes: wp.array(dtype=BvhNode), node: int, stop: int, start: wp.vec3,
                  inv: wp.vec3, max_t: float) -> wp.vec3i:  # fmt: skip
    """The library's stackless step (``mesh._next_ray_leaf``): the next leaf before
    ``stop`` whose box the ray meets by ``max_t``: ``(first, count, node after it)``."""
    n = node
    while n < stop:
        nd = nodes[n]
        if ray_box_enter(nd.lower, nd.upper, start, inv) <= max_t:
            if nd.first >= 0:
                return wp.vec3i(nd.first, nd.next, n + 1)
            n = n + 1
        else:
            n = skip_of(nd, n)
    return wp.vec3i(0, 0, stop)


@wp.func
def payload(nd: BvhNode, node: int) -> wp.vec2i:
    """A node's payload on right-linked nodes: a leaf's ``(first, count)``, an inner
    node's ``(left child, first)`` (``first = -1 - right``)."""
    if nd.first < 0:
        return wp.vec2i(node + 1, nd.first)
    return wp.vec2i(nd.first, nd.next)


@wp.func
def push(sa: wp.array(dtype=wp.int32), sb: wp.array(dtype=wp.int32),
         st: wp.array(dtype=wp.float32), count: int, a: int, b: int, t: float) -> int:  # fmt: skip
    """Payload ``(a, b)`` entered at ``t`` onto the stack of ``count`` entries: the new
    count (``STACK + 1``: full, the entry is lost)."""
    if count < STACK:
        sa[count] = a
        sb[count] = b
        st[count] = t
        return count + 1
    return STACK + 1


@wp.func
def push2(sa: wp.array(dtype=wp.int32), sb: wp.array(dtype=wp.int32), count: int, a: int,
          b: int) -> int:  # fmt: skip
    """``push`` without an entry ``t`` (the any-hit and count walks' stacks)."""
    if count < STACK:
        sa[count] = a
        sb[count] = b
        return count + 1
    return STACK + 1


def _arrays(by_address: bool):
    """``(nodes_of, items_of, tri_of)``: functions giving a BVH's nodes and item order
    and a mesh's corner copy, through the records' addresses (``by_address``: constant
    strides, ``packed_nodes``) or the records' arrays."""

    @wp.func
    def nodes_of(bvh: BvhRecord) -> wp.array(dtype=BvhNode):
        if wp.static(by_address):
            return packed_nodes(bvh)
        return bvh.nodes

    @wp.func
    def items_of(bvh: BvhRecord) -> wp.array(dtype=wp.int32):
        if wp.static(by_address):
            return tree_items(bvh)
        return bvh.items

    @wp.func
    def tri_of(rec: MeshRecord) -> wp.array(dtype=wp.vec3):
        if wp.static(by_address):
            return wp.array(ptr=rec.tri_ptr, shape=(rec.tri.shape[0],), dtype=wp.vec3)
        return rec.tri

    return nodes_of, items_of, tri_of


def _payload_walk(by_address: bool, split: bool, fallback: bool = True):
    """The payload walk on right-linked nodes (the library's since session 12, Warp's
    discipline) with its arrays read through the records' addresses (``by_address``)
    or the records' arrays, and its stackless pass in the loop after an overflow (one
    leaf-test site; without ``fallback``, -2 where the stack overflows) or, with
    ``split``, chosen before the walk, as the library does by the tree's height (here
    ``num_points < 0``, a load that is false, stands for it)."""
    nodes_of, items_of, tri_of = _arrays(by_address)

    @wp.func
    def walk(id: wp.uint64, start: wp.vec3, dir: wp.vec3, max_t: float) -> int:
        rec = wp.object_record(id, MeshRecord)
        bvh = wp.object_record(rec.bvh, BvhRecord)
        nodes = nodes_of(bvh)
        tri = tri_of(rec)
        items = items_of(bvh)
        shear = ray_shear(dir)
        inv = inverse(dir)
        hit = no_hit(max_t)
        span = root_range(bvh, -1)
        sa = wp.ext.empty(STACK, dtype=wp.int32)
        sb = wp.ext.empty(STACK, dtype=wp.int32)
        st = wp.ext.empty(STACK, dtype=wp.float32)
        count = 0
        lost = False
        sweep = span[1]
        active = False
        a = 0
        b = 0
        if span[0] < span[1]:
            nd = nodes[span[0]]
            active = ray_box_enter(nd.lower, nd.upper, start, inv) <= hit.t
            p = payload(nd, span[0])
            a = p[0]
            b = p[1]
        if wp.static(split):  # noqa: SIM102 - a static branch
            if rec.num_points < 0:  # (false: the library reads the tree's height here)
                node = span[0]
                while node < span[1]:
                    step = next_ray_leaf(nodes, node, span[1], start, inv, hit.t)
                    node = step[2]
                    hit = leaf_hits(tri, items, step[0], step[1], shear, start, hit)
                return hit.slot
        while active or (wp.static(fallback and not split) and sweep < span[1]):
            if active:
                while b < 0:  # an inner node: both children, loaded independently
                    right = -1 - b
                    left_nd = nodes[a]
                    right_nd = nodes[right]
                    t_l = ray_box_enter(left_nd.lower, left_nd.upper, start, inv)
                    t_r = ray_box_enter(right_nd.lower, right_nd.upper, start, inv)
                    l_in = t_l <= hit.t
                    r_in = t_r <= hit.t
                    lp = payload(left_nd, a)
                    rp = payload(right_nd, right)
                    if r_in and (not l_in or t_r < t_l):  # the right child first
                        if l_in:
                            count = push(sa, sb, st, count, lp[0], lp[1], t_l)
                        a = rp[0]
                        b = rp[1]
                    elif l_in:
                        if r_in:
                            count = push(sa, sb, st, count, rp[0], rp[1], t_r)
                        a = lp[0]
                        b = lp[1]
                    else:
                        b = 0  # both missed: nothing to test
                    if count > STACK:
                        count = STACK
                        lost = True
                        if wp.static(fallback and not split):
                            sweep = span[0]
            else:
                step = next_ray_leaf(nodes, sweep, span[1], start, inv, hit.t)
                sweep = step[2]
                a = step[0]
                b = step[1]
            hit = leaf_hits(tri, items, a, b, shear, start, hit)
            active = False
            while count > 0 and not active:
                count = count - 1
                if st[count] <= hit.t:
                    a = sa[count]
                    b = sb[count]
                    active = True
        if wp.static(not fallback):  # noqa: SIM102 - a static branch
            if lost:
                return -2
        return hit.slot

    return walk


@wp.func
def wait_links(nodes: wp.array(dtype=wp.int32), keys: wp.array(dtype=wp.float32),
               links: wp.array(dtype=wp.vec3i), count: int, node: int, key: float,
               first: int, next: int, right: int) -> int:  # fmt: skip
    if count < STACK:
        nodes[count] = node
        keys[count] = key
        links[count] = wp.vec3i(first, next, right)
    return count + 1


@wp.func
def prefetch_walk(id: wp.uint64, start: wp.vec3, dir: wp.vec3, max_t: float) -> int:
    """Session 11's library search (``8318df0``), on today's nodes: an inner node is
    carried with its right child read from the ``skip`` array a level ahead (its
    packed ``first`` is not used: only its sign), a waiting node keeps its links, and
    the stackless fallback."""
    rec = wp.object_record(id, MeshRecord)
    bvh = wp.object_record(rec.bvh, BvhRecord)
    shear = ray_shear(dir)
    inv = inverse(dir)
    hit = no_hit(max_t)
    span = root_range(bvh, -1)
    nodes = wp.ext.empty(STACK, dtype=wp.int32)
    enters = wp.ext.empty(STACK, dtype=wp.float32)
    links = wp.ext.empty(STACK, dtype=wp.vec3i)
    last = bvh.skip.shape[0] - 1
    count = 0
    sweep = span[1]
    node = span[0]
    active = False
    first = 0
    items = 0
    right = 0  # the right child of ``node`` while it is an inner node
    if span[0] < span[1]:
        nd = bvh.nodes[node]
        active = ray_box_enter(nd.lower, nd.upper, start, inv) <= hit.t
        first = nd.first
        items = nd.next
        right = bvh.skip[wp.min(node + 1, last)]
    while active or sweep < span[1]:
        if active:
            while first < 0:
                left = node + 1
                left_nd = bvh.nodes[left]
                right_nd = bvh.nodes[right]
                left_right = bvh.skip[wp.min(left + 1, last)]
                right_right = bvh.skip[wp.min(right + 1, last)]
                t_left = ray_box_enter(left_nd.lower, left_nd.upper, start, inv)
                t_right = ray_box_enter(right_nd.lower, right_nd.upper, start, inv)
                left_in = t_left <= hit.t
                right_in = t_right <= hit.t
                go_right = right_in and (not left_in or t_right < t_left)
                if left_in and right_in:
                    if go_right:
                        count = wait_links(nodes, enters, links, count, left, t_left,
                                           left_nd.first, left_nd.next, left_right)  # fmt: skip
                    else:
                        count = wait_links(nodes, enters, links, count, right, t_right,
                                           right_nd.first, right_nd.next, right_right)  # fmt: skip
                    if count > STACK:
                        count = STACK
                        sweep = span[0]
                if go_right:
                    node = right
                    first = right_nd.first
                    items = right_nd.next
                    right = right_right
                elif left_in:
                    node = left
                    first = left_nd.first
                    items = left_nd.next
                    right = left_right
                else:
                    first = 0
                    items = 0
        else:
            step = next_ray_leaf(bvh.nodes, sweep, span[1], start, inv, hit.t)
            sweep = step[2]
            first = step[0]
            items = step[1]
        hit = leaf_hits(rec.tri, bvh.items, first, items, shear, start, hit)
        active = False
        while count > 0 and not active:
            count = count - 1
            if enters[count] <= hit.t:
                node = nodes[count]
                link = links[count]
                first = link[0]
                items = link[1]
                right = link[2]
                active = True
    return hit.slot


def _stackless_count(stop_at_first: bool, by_address: bool):
    """The library's any hit (``mesh_query_ray_anyhit``: stackless, leaf to leaf; 1 or 0)
    or, without ``stop_at_first``, its counted hits, on the records' arrays or
    (``by_address``) through their addresses."""
    nodes_of, _items_of, tri_of = _arrays(by_address)

    @wp.func
    def walk(id: wp.uint64, start: wp.vec3, dir: wp.vec3, max_t: float) -> int:
        rec = wp.object_record(id, MeshRecord)
        bvh = wp.object_record(rec.bvh, BvhRecord)
        nodes = nodes_of(bvh)
        tri = tri_of(rec)
        shear = ray_shear(dir)
        inv = inverse(dir)
        found = 0
        span = root_range(bvh, -1)
        node = span[0]
        while node < span[1] and (found == 0 or not wp.static(stop_at_first)):
            step = next_ray_leaf(nodes, node, span[1], start, inv, max_t)
            node = step[2]
            found = found + leaf_count(tri, step[0], step[1], shear, start, max_t)
        if wp.static(stop_at_first):
            return wp.min(found, 1)
        return found

    return walk


def _stack_count_walk(stop_at_first: bool, nearer_first: bool, by_address: bool = False):
    """Hits counted on the right-linked nodes with a stack of payloads (no entry ``t``:
    every box the ray meets before ``max_t`` is entered): a level loads both children
    at once; ``stop_at_first``: the any hit (1 or 0); ``nearer_first``: the child the
    ray enters first is visited first, else the left one; ``by_address``: the arrays
    through the records' addresses. -2 on a stack overflow."""
    nodes_of, _items_of, tri_of = _arrays(by_address)

    @wp.func
    def walk(id: wp.uint64, start: wp.vec3, dir: wp.vec3, max_t: float) -> int:
        rec = wp.object_record(id, MeshRecord)
        bvh = wp.object_record(rec.bvh, BvhRecord)
        nodes = nodes_of(bvh)
        tri = tri_of(rec)
        shear = ray_shear(dir)
        inv = inverse(dir)
        sa = wp.ext.empty(STACK, dtype=wp.int32)
        sb = wp.ext.empty(STACK, dtype=wp.int32)
        count = 0
        lost = False
        found = 0
        root = bvh.root
        active = False
        a = 0
        b = 0
        if root >= 0:
            nd = nodes[root]
            active = ray_box_enter(nd.lower, nd.upper, start, inv) <= max_t
            p = payload(nd, root)
            a = p[0]
            b = p[1]
        while active:
            while b < 0:
                right = -1 - b
                left_nd = nodes[a]
                right_nd = nodes[right]
                t_l = ray_box_enter(left_nd.lower, left_nd.upper, start, inv)
                t_r = ray_box_enter(right_nd.lower, right_nd.upper, start, inv)
                l_in = t_l <= max_t
                r_in = t_r <= max_t
                lp = payload(left_nd, a)
                rp = payload(right_nd, right)
                go_right = r_in and not l_in
                if wp.static(nearer_first):
                    go_right = r_in and (not l_in or t_r < t_l)
                if go_right:
                    if l_in:
                        count = push2(sa, sb, count, lp[0], lp[1])
                    a = rp[0]
                    b = rp[1]
                elif l_in:
                    if r_in:
                        count = push2(sa, sb, count, rp[0], rp[1])
                    a = lp[0]
                    b = lp[1]
                else:
                    b = 0
                if count > STACK:
                    lost = True
                    count = STACK
            found = found + leaf_count(tri, a, b, shear, start, max_t)
            active = count > 0
            if wp.static(stop_at_first):
                active = active and found == 0
            if active:
                count = count - 1
                a = sa[count]
                b = sb[count]
        if lost:
            return -2
        if wp.static(stop_at_first):
            return wp.min(found, 1)
        return found

    return walk


@wp.func
def closest_in_leaf(tri: wp.array(dtype=wp.vec3), items: wp.array(dtype=wp.int32), first: int,
                    count: int, point: wp.vec3, best: wp.vec2) -> wp.vec2:  # fmt: skip
    """The library's leaf test of the closest point: ``best`` is (squared distance,
    face as a float)."""
    out = best
    for k in range(first, first + count):
        a = tri[k * 3]
        b = tri[k * 3 + 1]
        c = tri[k * 3 + 2]
        uv = closest_point_to_triangle(a, b, c, point)
        q = a * uv[0] + b * uv[1] + c * (1.0 - uv[0] - uv[1])
        d = wp.length_sq(q - point)
        if d <= out[0]:
            f = items[k]
            if d < out[0] or (out[1] >= 0.0 and float(f) < out[1]):  # noqa: SIM102
                if not is_sliver(a, b, c):
                    out = wp.vec2(d, float(f))
    return out


@wp.func
def next_near_leaf(nodes: wp.array(dtype=BvhNode), node: int, stop: int, point: wp.vec3,
                   bound_sq: float) -> wp.vec3i:  # fmt: skip
    n = node
    while n < stop:
        nd = nodes[n]
        if box_distance_sq(nd.lower, nd.upper, point) <= bound_sq:
            if nd.first >= 0:
                return wp.vec3i(nd.first, nd.next, n + 1)
            n = n + 1
        else:
            n = skip_of(nd, n)
    return wp.vec3i(0, 0, stop)


def _closest_walk(far_from_link: bool, by_address: bool):
    """The library's closest-point search (``mesh._closest_face``'s binary walk): the
    far child from the inner node's right link (``far_from_link``: both child loads at
    once, since ``364b2f8``) or, before, from the near child's node (``skip``: the far
    load waited for the near one's); the arrays through the records' addresses
    (``by_address``) or the records' arrays."""
    nodes_of, items_of, tri_of = _arrays(by_address)

    @wp.func
    def walk(id: wp.uint64, point: wp.vec3, max_dist: float) -> int:
        rec = wp.object_record(id, MeshRecord)
        bvh = wp.object_record(rec.bvh, BvhRecord)
        tree = nodes_of(bvh)
        tri = tri_of(rec)
        items = items_of(bvh)
        best = wp.vec2(max_dist * max_dist, -1.0)
        span = root_range(bvh, -1)
        nodes = wp.ext.empty(STACK, dtype=wp.int32)
        dists = wp.ext.empty(STACK, dtype=wp.float32)
        count = 0
        sweep = span[1]
        if span[0] < span[1]:
            nodes[0] = span[0]
            dists[0] = 0.0
            count = 1
        while count > 0 or sweep < span[1]:
            first = 0
            leaf_items = 0
            if count == 0:
                step = next_near_leaf(tree, sweep, span[1], point, best[0])
                sweep = step[2]
                first = step[0]
                leaf_items = step[1]
            else:
                count = count - 1
                node = nodes[count]
                if dists[count] <= best[0]:
                    nd = tree[node]
                    inner = nd.first < 0
                    while inner:
                        near = node + 1
                        far = -1 - nd.first  # (the link; before: the near child's skip)
                        near_nd = tree[near]
                        if wp.static(not far_from_link):
                            far = skip_of(near_nd, near)
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
                        if d_far <= best[0]:
                            if count < STACK:
                                nodes[count] = far
                                dists[count] = d_far
                            count = count + 1
                            if count > STACK:
                                count = STACK
                                sweep = span[0]
                        inner = False
                        if d_near <= best[0]:
                            node = near
                            nd = near_nd
                            inner = nd.first < 0
                    if nd.first >= 0:
                        first = nd.first
                        leaf_items = nd.next
            best = closest_in_leaf(tri, items, first, leaf_items, point, best)
        return int(best[1])

    return walk


@wp.func
def finish(id: wp.uint64, slot: int, start: wp.vec3, dir: wp.vec3) -> wp.vec2:
    """The library's tail after the search: the hit recomputed from its slot (``t``,
    face as a float; face -1 for a miss)."""
    if slot < 0:
        return wp.vec2(0.0, float(slot))
    rec = wp.object_record(id, MeshRecord)
    a = rec.tri[slot * 3]
    b = rec.tri[slot * 3 + 1]
    c = rec.tri[slot * 3 + 2]
    h = intersect_ray_triangle(ray_shear(dir), start, a, b, c)
    face = wp.object_record(rec.bvh, BvhRecord).items[slot]
    return wp.vec2(h[0], float(face))


def _library_count(m):
    """The counted-hits kernel against module ``m`` (kdsl or warp): ``face[i]`` the count."""

    @m.kernel(enable_backward=False)
    def count(mesh: m.uint64, start: m.array(dtype=m.vec3), d: m.array(dtype=m.vec3),
              face: m.array(dtype=m.int32), t: m.array(dtype=float)):  # fmt: skip
        i = m.tid()
        face[i] = m.mesh_query_ray_count_intersections(mesh, start[i], d[i])

    return count


def _library_point(m):
    """The closest-point kernel against module ``m``: ``face[i]`` the face (-1: none),
    ``t[i]`` its ``u`` (the rays' ``start`` are the query points)."""

    @m.kernel(enable_backward=False)
    def point(mesh: m.uint64, start: m.array(dtype=m.vec3), d: m.array(dtype=m.vec3),
              face: m.array(dtype=m.int32), t: m.array(dtype=float)):  # fmt: skip
        i = m.tid()
        q = m.mesh_query_point_no_sign(mesh, start[i], MAX_DIST)
        face[i] = -1
        if q.result:
            face[i] = q.face
            t[i] = q.u

    return point


def _library_any(m):
    """The any-hit kernel against module ``m``: ``face[i]`` 1 on a hit, else 0."""

    @m.kernel(enable_backward=False)
    def anyhit(mesh: m.uint64, start: m.array(dtype=m.vec3), d: m.array(dtype=m.vec3),
               face: m.array(dtype=m.int32), t: m.array(dtype=float)):  # fmt: skip
        i = m.tid()
        face[i] = 0
        if m.mesh_query_ray_anyhit(mesh, start[i], d[i], MAX_T):
            face[i] = 1

    return anyhit


def variant_kernel(walk: str, regs: int | None = None):
    """The kernel of one variant: ``face[i]``, ``t[i]`` of ray ``i`` (any hit and
    counts: ``face[i]`` only). ``walk``: "lib" (``mesh_query_ray``), "prefetch",
    "payload", "any_lib", "any_stack", "any_near", "count_lib" or "count_stack";
    ``regs``: the kernel option ``cuda_max_registers``."""
    options = {} if regs is None else {"cuda_max_registers": regs}
    if walk == "lib":  # the mesh benchmark's ray kernel (one source for kdsl and Warp)
        return wp.kernel(mesh_kernels(wp)[1].fn, enable_backward=False, **options)
    if walk == "any_lib":
        return _library_any(wp)
    if walk == "count_lib":
        return _library_count(wp)
    if walk == "point_lib":
        return _library_point(wp)
    if walk in ("point_skip", "point_link", "point_addr"):
        closest = _closest_walk(walk != "point_skip", walk == "point_addr")

        @wp.kernel(enable_backward=False, **options)
        def point(mesh: wp.uint64, start: wp.array(dtype=wp.vec3),
                  d: wp.array(dtype=wp.vec3), face: wp.array(dtype=wp.int32),
                  t: wp.array(dtype=float)):  # fmt: skip
            i = wp.tid()
            f = closest(mesh, start[i], MAX_DIST)
            face[i] = f
            if f >= 0:  # the library's tail: the barycentrics on the face found
                a = wp.mesh_get_point(mesh, f * 3)
                b = wp.mesh_get_point(mesh, f * 3 + 1)
                c = wp.mesh_get_point(mesh, f * 3 + 2)
                t[i] = closest_point_to_triangle(a, b, c, start[i])[0]

        return point
    if walk in ("any_stack", "any_near", "count_stack", "count_stack_addr", "any_addr",
                "any_rec", "count_rec"):  # fmt: skip
        if walk in ("any_addr", "any_rec", "count_rec"):
            hits = _stackless_count(walk.startswith("any"), walk == "any_addr")
        else:
            hits = _stack_count_walk(walk.startswith("any"), walk == "any_near",
                                     walk.endswith("_addr"))  # fmt: skip

        @wp.kernel(enable_backward=False, **options)
        def counted(mesh: wp.uint64, start: wp.array(dtype=wp.vec3),
                    d: wp.array(dtype=wp.vec3), face: wp.array(dtype=wp.int32),
                    t: wp.array(dtype=float)):  # fmt: skip
            i = wp.tid()
            face[i] = hits(mesh, start[i], d[i], MAX_T)

        return counted
    if walk == "prefetch":
        search = prefetch_walk
    else:  # onesite, payload, addr, split, split_rec
        search = _payload_walk(walk in ("addr", "split"), walk.startswith("split"),
                               walk != "payload")  # fmt: skip

    @wp.kernel(enable_backward=False, **options)
    def rays(mesh: wp.uint64, start: wp.array(dtype=wp.vec3), d: wp.array(dtype=wp.vec3),
             face: wp.array(dtype=wp.int32), t: wp.array(dtype=float)):  # fmt: skip
        i = wp.tid()
        slot = search(mesh, start[i], d[i], MAX_T)
        r = finish(mesh, slot, start[i], d[i])
        face[i] = int(r[1])
        t[i] = r[0]

    return rays


def _time(fn, reps: int, sync) -> float:
    fn()
    sync()
    best = float("inf")
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        sync()
        best = min(best, time.perf_counter() - t0)
    return best


def _warp_side(data: dict, device: str, reps: int, families: set[str]) -> dict:
    """Warp's rows for ``families``: name -> (seconds, face, t)."""
    import warp

    warp.config.quiet = True
    warp.init()
    pts = warp.array(data["points"], dtype=warp.vec3, device=device)
    idx = warp.array(data["faces"].reshape(-1), dtype=warp.int32, device=device)
    mesh = warp.Mesh(pts, idx)
    n = len(data["ray_start"])
    s = warp.array(data["ray_start"], dtype=warp.vec3, device=device)
    d = warp.array(data["ray_dir"], dtype=warp.vec3, device=device)
    xs = warp.array(data["points_q"][:n], dtype=warp.vec3, device=device)
    kernels = {"ray": mesh_kernels(warp)[1], "any": _library_any(warp),
               "count": _library_count(warp), "point": _library_point(warp)}  # fmt: skip
    out = {}
    for fam in sorted(families):
        k = kernels[fam]
        face = warp.zeros(n, dtype=warp.int32, device=device)
        t = warp.zeros(n, dtype=float, device=device)

        def run(k=k, face=face, t=t, at=xs if fam == "point" else s):
            warp.launch(k, n, [mesh.id, at, d, face, t], device=device)

        secs = _time(run, reps, lambda: warp.synchronize_device(device))
        out[FAMILIES[fam][1]] = (secs, face.numpy(), t.numpy())
    return out


def _check(rows: list[dict], answers: dict, n: int) -> bool:
    """Compare each row's answers with its family's reference (exactly) and each
    reference's with Warp's (hit/miss, ``t`` within 1e-5, counts); fills the rows'
    ``face_diff``/``t_diff``; whether all agree."""
    ok = True
    for row in rows:
        name = row["variant"]
        fam = row["family"]
        ref, warp_name = FAMILIES[fam]
        lf, lt = answers[ref]
        f, t = answers[name]
        if name == warp_name:  # Warp against the reference
            if fam in ("ray", "point"):  # hit or miss (points: faces may tie)
                row["face_diff"] = int(((f >= 0) != (lf >= 0)).sum())
                both = (f >= 0) & (lf >= 0) & (fam == "ray")
                row["t_diff"] = int((np.abs(t - lt) > 1e-5 * np.maximum(1, np.abs(lt)))[both].sum())
            else:
                row["face_diff"], row["t_diff"] = int((f != lf).sum()), 0
            ok &= row["face_diff"] <= RAY_DISAGREEMENT * n
        else:
            row["face_diff"] = int((f != lf).sum())
            row["t_diff"] = int(((t != lt) & (lf >= 0)).sum()) if fam in ("ray", "point") else 0
            ok &= row["face_diff"] == 0 and row["t_diff"] == 0
    return ok


def main(argv: list[str] | None = None) -> int:
    """Run the variants (and Warp), print the table, check the answers; exit status 1
    when an answer disagrees."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tris", type=int, default=200_000)
    ap.add_argument("--rays", type=int, default=1_000_000)
    ap.add_argument("--reps", type=int, default=20)
    ap.add_argument("--device", default="cuda:0")
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--no-warp", action="store_true")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    dev = args.device
    data = workload(args.tris, args.rays)
    n = len(data["ray_start"])
    mesh = wp.Mesh(wp.array(data["points"], dtype=wp.vec3, device=dev),
                   wp.array(data["faces"].reshape(-1), dtype=wp.int32, device=dev))  # fmt: skip
    s = wp.array(data["ray_start"], dtype=wp.vec3, device=dev)
    d = wp.array(data["ray_dir"], dtype=wp.vec3, device=dev)
    xs = wp.array(data["points_q"][:n], dtype=wp.vec3, device=dev)  # the point family's
    names = ["lib", *(v for v in args.variants.split(",") if v and v != "lib")]
    for name in names:
        if name not in VARIANTS and name != "lib":
            ap.error(f"unknown variant {name!r}; choose from {', '.join(VARIANTS)}")
    families = {family(v) for v in names}
    for fam in families:  # each family's reference runs too
        if FAMILIES[fam][0] not in names:
            names.append(FAMILIES[fam][0])
    rows: list[dict] = []
    answers: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    if not args.no_warp:
        for name, (secs, face, t) in _warp_side(data, dev, args.reps, families).items():
            fam = next(f for f, (_, w) in FAMILIES.items() if w == name)
            rows.append({"variant": name, "family": fam, "ms": secs * 1e3})
            answers[name] = (face, t)
    for name in names:
        k = variant_kernel("lib") if name == "lib" else variant_kernel(**VARIANTS[name])
        face = wp.zeros(n, dtype=wp.int32, device=dev)
        t = wp.zeros(n, dtype=float, device=dev)

        at = xs if family(name) == "point" else s

        def run(k=k, face=face, t=t, at=at):
            wp.launch(k, n, [mesh.id, at, d, face, t], device=dev)

        secs = _time(run, args.reps, lambda: wp.synchronize_device(dev))
        answers[name] = (face.numpy(), t.numpy())
        rows.append({"variant": name, "family": family(name), "ms": secs * 1e3})
    ok = _check(rows, answers, n)
    warp_ms = {r["family"]: r["ms"] for r in rows if r["variant"].startswith("warp")}
    for row in rows:
        if row["family"] in warp_ms:
            row["vs_warp"] = warp_ms[row["family"]] / row["ms"]
    rows.sort(key=lambda r: list(FAMILIES).index(r["family"]))
    print(f"{n} rays, {len(data['faces'])} triangles, {dev}, min of {args.reps} launches")
    print(f"{'variant':<26}{'ms':>8}{'x Warp':>8}{'face diff':>11}{'t diff':>8}")
    for r in rows:
        print(f"{r['variant']:<26}{r['ms']:8.3f}{r.get('vs_warp', float('nan')):8.2f}"
              f"{r['face_diff']:11d}{r['t_diff']:8d}")  # fmt: skip
    if args.json:
        Path(args.json).write_text(json.dumps({"rows": rows, "n": n}, indent=1))
    if not ok:
        print("ANSWERS DISAGREE")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
