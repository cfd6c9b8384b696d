"""A mesh's BVH collapsed to four children a node, for the CPU's closest-point walk.

``WideTree`` keeps, beside a mesh's binary ``kdsl.Bvh``, the same tree with four
children a node in the SoA layout of ``kdsl.stdlib.mesh_wide`` (``WideNode``,
``WideLeaf``), which the closest-point queries walk with vector instructions. Where a
mesh keeps one is decided here, once, by device kind (``WIDE_TREE``): the CPU, where
it measured faster (docs/performance.md, "CPU closest points: a 4-wide tree"); a GPU
walks the binary tree. docs/geometry.md ("Wide tree") describes the layout.

The collapse (``rebuild``, after every build of the binary tree) is one kdsl kernel
run by one thread: from the root, depth first (so a subtree's wide nodes, and its
leaves, are numbered consecutively), each wide node takes its binary node's two
children and splits the one of largest surface area into its own two, until it has
four or only leaves are left, where a leaf is any binary subtree of at most four
faces whose faces are consecutive in the item order (so two small sibling leaves
share one wide leaf). It writes the topology (``WideNode.child``, ``src``) and
each wide leaf's faces; ``refit`` (after every refit of the binary tree, so also after
the points moved) copies each child's box from its binary node and gathers the
leaves' corners from the mesh's vertex copy in item order (``TreePoints.tri``, where
a leaf's faces are consecutive) in parallel kernels.
"""

from __future__ import annotations

from typing import Any

from kdsl.frontend.api import func, inout, kernel, static, tid
from kdsl.frontend.constants import nan
from kdsl.geometry.bvh import Bvh
from kdsl.geometry.mesh_tree_points import TreePoints
from kdsl.runtime.alloc import clone, empty
from kdsl.runtime.array import array
from kdsl.runtime.launch import launch
from kdsl.runtime.objects import ObjectRecord
from kdsl.stdlib.bvh import BvhNode
from kdsl.stdlib.mesh_primitives import is_sliver
from kdsl.stdlib.mesh_wide import WideLeaf, WideNode, WideRecord
from kdsl.types import float32, int32, vec2i, vec3, vec4, vec4i

#: Whether a mesh keeps a 4-wide tree, per device kind (the one place this is chosen).
WIDE_TREE = {"cpu": True, "cuda": False}
#: The most faces a wide leaf holds (its four lanes).
LANES = 4
#: ``_collapse``'s status when a binary leaf holds more faces than a wide leaf.
_REFUSED = 1


@func
def _end(nodes: array(dtype=BvhNode), n: int) -> int:
    """The node after the subtree of binary node ``n`` (preorder)."""
    nd = nodes[n]
    if nd.first >= 0:
        return n + 1
    return nd.next


@func
def _small(nodes: array(dtype=BvhNode), n: int) -> vec2i:
    """``(first, count)`` of the faces of binary node ``n``'s subtree when it holds at
    most ``LANES`` of them, at consecutive positions of the item order; count -1
    otherwise. Reads at most a few nodes: it stops past ``LANES`` faces."""
    end = _end(nodes, n)
    first = -1
    total = 0
    m = n
    while m < end and total >= 0:
        nd = nodes[m]
        if nd.first >= 0:
            if first < 0:
                first = nd.first
            if nd.first != first + total or total + nd.next > LANES:
                total = -1
            else:
                total = total + nd.next
        m = m + 1
    return vec2i(first, total)


@func
def _area(nodes: array(dtype=BvhNode), n: int) -> float:
    """Half the surface area of binary node ``n``'s box."""
    nd = nodes[n]
    e = nd.upper - nd.lower
    return e[0] * e[1] + e[1] * e[2] + e[2] * e[0]


@func
def _candidate(
    nodes: array(dtype=BvhNode), n: int, at: int, kids: inout(vec4i), firsts: inout(vec4i),
    counts: inout(vec4i), areas: inout(vec4),
):  # fmt: skip
    """Binary node ``n`` as a wide node's child ``at``: a wide leaf (``_small``: its
    faces' first position and count) or a node (count -1, and its box's half area, to
    pick the next split)."""
    r = _small(nodes, n)
    kids[at] = n
    firsts[at] = r[0]
    counts[at] = r[1]
    areas[at] = float32(0.0)
    if r[1] < 0:
        areas[at] = _area(nodes, n)


@func
def _children(
    nodes: array(dtype=BvhNode), b: int, kids: inout(vec4i), firsts: inout(vec4i),
    counts: inout(vec4i),
):  # fmt: skip
    """The (up to) four binary nodes under inner node ``b`` that become a wide node's
    children (``kids``, -1: an empty slot): ``b``'s two, then the largest (by area)
    that is not a wide leaf split into its two, until four or only wide leaves; with
    each wide leaf's faces (``firsts``, ``counts``; count -1 for a node)."""
    kids = vec4i(b + 1, _end(nodes, b + 1), -1, -1)
    areas = vec4(float32(0.0))
    for j in range(static(2)):
        _candidate(nodes, kids[j], j, kids, firsts, counts, areas)
    k = 2
    while k < LANES:
        pick = -1
        for j in range(static(LANES)):
            if j < k and counts[j] < 0 and (pick < 0 or areas[j] > areas[pick]):
                pick = j
        if pick < 0:
            k = LANES
        else:
            split = kids[pick]
            _candidate(nodes, split + 1, pick, kids, firsts, counts, areas)
            _candidate(nodes, _end(nodes, split + 1), k, kids, firsts, counts, areas)
            k = k + 1


@kernel
def _collapse(
    nodes: array(dtype=BvhNode), stack: array(dtype=int32),
    parents: array(dtype=int32), child: array(dtype=vec4i), src: array(dtype=vec4i),
    spans: array(dtype=vec2i), counts: array(dtype=int32),
):  # fmt: skip
    # One thread, depth first (a subtree's wide nodes and leaves are numbered
    # consecutively): binary node stack[t] becomes the next wide node, linked into
    # lane parents[t] % 4 of wide node parents[t] / 4 (-1: the root); writes child[w],
    # src[w] and each wide leaf's faces (spans: first position in the items, count);
    # counts = (wide nodes, wide leaves, status).
    num_nodes = 0
    num_leaves = 0
    status = 0
    stack[0] = 0
    parents[0] = -1
    top = 1
    while top > 0:
        top = top - 1
        b = stack[top]
        w = num_nodes
        num_nodes = num_nodes + 1
        up = parents[top]
        if up >= 0:
            link = child[up // LANES]
            link[up % LANES] = w
            child[up // LANES] = link
        kids = vec4i(b, -1, -1, -1)  # a root of at most four faces: one leaf under the root
        r = _small(nodes, b)
        firsts = vec4i(r[0], 0, 0, 0)
        sizes = vec4i(r[1], 0, 0, 0)
        if r[1] < 0:
            if nodes[b].first >= 0:
                status = _REFUSED  # a binary leaf of more faces than a wide leaf's lanes
            else:
                _children(nodes, b, kids, firsts, sizes)
        links = vec4i(-1)
        for j in range(static(LANES)):
            n = kids[j]
            if n >= 0:
                if sizes[j] >= 0:
                    spans[num_leaves] = vec2i(firsts[j], sizes[j])
                    links[j] = -num_leaves - 1
                    num_leaves = num_leaves + 1
                elif nodes[n].first >= 0:
                    status = _REFUSED
        for jj in range(static(LANES)):  # the wide nodes below, lane 0 on top
            j = LANES - 1 - jj
            n = kids[j]
            if n >= 0 and sizes[j] < 0 and nodes[n].first < 0:
                stack[top] = n
                parents[top] = w * LANES + j
                top = top + 1
        child[w] = links
        src[w] = kids
        if status != 0:
            top = 0  # (stop: the mesh walks its binary tree)
    counts[0] = num_nodes
    counts[1] = num_leaves
    counts[2] = status


@func
def _lane_boxes(nd: WideNode, bnodes: array(dtype=BvhNode)) -> WideNode:
    """``nd`` with each child's box copied from its binary node (NaN: an empty slot)."""
    out = nd
    for i in range(static(LANES)):
        lo = vec3(float32(nan))
        hi = vec3(float32(nan))
        s = nd.src[i]
        if s >= 0:
            b = bnodes[s]
            lo = b.lower
            hi = b.upper
        out.lo_x[i] = lo[0]
        out.lo_y[i] = lo[1]
        out.lo_z[i] = lo[2]
        out.hi_x[i] = hi[0]
        out.hi_y[i] = hi[1]
        out.hi_z[i] = hi[2]
    return out


@kernel
def _init_nodes(
    child: array(dtype=vec4i), src: array(dtype=vec4i), bnodes: array(dtype=BvhNode),
    out: array(dtype=WideNode),
):  # fmt: skip
    w = tid()
    nd = WideNode()
    nd.child = child[w]
    nd.src = src[w]
    out[w] = _lane_boxes(nd, bnodes)


@kernel
def _refit_nodes(bnodes: array(dtype=BvhNode), nodes: array(dtype=WideNode)):
    w = tid()
    nodes[w] = _lane_boxes(nodes[w], bnodes)


@kernel
def _gather_leaves(
    tri: array(dtype=vec3), items: array(dtype=int32), spans: array(dtype=vec2i),
    leaves: array(dtype=WideLeaf),
):  # fmt: skip
    # Leaf k's lanes: the corners of the faces at its item positions, read from the
    # mesh's vertex copy in item order (consecutive: no index loads; zero in an empty
    # lane), and the faces' numbers (-1 for an empty lane or a sliver).
    k = tid()
    span = spans[k]
    lf = WideLeaf()
    lf.face = vec4i(-1)
    for i in range(static(LANES)):
        a = vec3(float32(0.0))
        b = vec3(float32(0.0))
        c = vec3(float32(0.0))
        if i < span[1]:
            at = span[0] + i
            a = tri[at * 3]
            b = tri[at * 3 + 1]
            c = tri[at * 3 + 2]
            if not is_sliver(a, b, c):
                lf.face[i] = items[at]
        lf.ax[i] = a[0]
        lf.ay[i] = a[1]
        lf.az[i] = a[2]
        lf.bx[i] = b[0]
        lf.by[i] = b[1]
        lf.bz[i] = b[2]
        lf.cx[i] = c[0]
        lf.cy[i] = c[1]
        lf.cz[i] = c[2]
    leaves[k] = lf


def wants_wide_tree(device: Any, leaf_size: int) -> bool:
    """Whether a mesh on ``device`` whose BVH has leaves of at most ``leaf_size`` faces
    keeps a 4-wide tree (``WIDE_TREE``; never for leaves wider than a wide leaf)."""
    return WIDE_TREE["cuda" if device.is_cuda else "cpu"] and leaf_size <= LANES


class WideTree:
    """A mesh's 4-wide tree (``kdsl.stdlib.mesh_wide.WideRecord``; ``id`` for the mesh's
    record). ``tree_points`` is the mesh's ``TreePoints``, whose vertex copy (``tri``,
    in the BVH's item order, written before the wide tree is) the leaves are gathered
    from. ``rebuild(bvh)`` collapses the binary
    tree again (after it was built), ``refit(bvh)`` refreshes the boxes and corners
    (after it was refit)."""

    def __init__(self, tree_points: TreePoints, device: Any) -> None:
        self.tree_points = tree_points
        self.device = device
        self._record = ObjectRecord(self, WideRecord.__kdsl_type__, "mesh wide tree", device)
        self.nodes: array | None = None
        self.leaves: array | None = None
        self._spans: array | None = None

    @property
    def id(self) -> int:
        """The record's id (a ``uint64``), for ``MeshRecord.wide``."""
        return self._record.id

    def rebuild(self, bvh: Bvh) -> None:
        """Collapse ``bvh``'s tree (current bounds) and gather the leaves."""
        dev = self.device
        tris = self.tree_points.indices.shape[0] // 3
        cap = max(tris, 1)  # at most one wide node and one wide leaf per face
        stack, parents = (empty(cap, dtype=int32, device=dev) for _ in range(2))
        child, src = (empty(cap, dtype=vec4i, device=dev) for _ in range(2))
        spans = empty(cap, dtype=vec2i, device=dev)
        counts = empty(3, dtype=int32, device=dev)
        num_nodes = num_leaves = status = 0
        if tris > 0:
            launch(_collapse, dim=1, device=dev,
                   inputs=[bvh.packed_nodes, stack, parents, child, src, spans, counts])  # fmt: skip
            num_nodes, num_leaves, status = (int(x) for x in counts.numpy())
        if status != 0:
            num_nodes = num_leaves = 0
        self.nodes = empty(num_nodes, dtype=WideNode, device=dev)
        self.leaves = empty(num_leaves, dtype=WideLeaf, device=dev)
        self._spans = clone(spans[:num_leaves])
        if num_nodes:
            launch(_init_nodes, dim=num_nodes, device=dev,
                   inputs=[child[:num_nodes], src[:num_nodes], bvh.packed_nodes, self.nodes])  # fmt: skip
        self._gather(bvh)
        self._record.write({"nodes": self.nodes, "leaves": self.leaves, "fallback": status})

    def refit(self, bvh: Bvh) -> None:
        """Copy the children's boxes from ``bvh``'s refit nodes; gather the corners again."""
        if self.nodes.shape[0]:
            launch(_refit_nodes, dim=self.nodes.shape[0], device=self.device,
                   inputs=[bvh.packed_nodes, self.nodes])  # fmt: skip
        self._gather(bvh)

    def _gather(self, bvh: Bvh) -> None:
        if self.leaves.shape[0]:
            launch(_gather_leaves, dim=self.leaves.shape[0], device=self.device,
                   inputs=[self.tree_points.tri, bvh.item_order, self._spans, self.leaves])  # fmt: skip
