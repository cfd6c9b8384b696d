"""A mesh's BVH collapsed to four children a node, for the CPU's closest-point walk.

``WideTree`` keeps, beside a mesh's binary ``kdsl.Bvh``, the same tree with four
children a node in the SoA layout of ``kdsl.stdlib.mesh_wide`` (``WideNode``,
``WideLeaf``), which the closest-point queries walk with vector instructions. Where a
mesh keeps one is decided here, once, by device kind (``WIDE_TREE``): the CPU, where
it measured faster (docs/performance.md, "CPU closest points: a 4-wide tree"); a GPU
walks the binary tree. docs/geometry.md ("Wide tree") describes the layout.

``rebuild`` (after every build of the binary tree) collapses it
(``kdsl.geometry.wide_collapse``: the topology, and a cut of the tree into subtrees,
the tasks), writes each wide node's links and boxes and fills the leaves from the
mesh's vertex copy in item order (``TreePoints.tri``, where a leaf's faces are
consecutive). ``refit`` (the CPU mesh's whole refit, after its check) updates the
vertex copy, the binary tree's bounds and the wide tree together, in one pass over the
tasks (each worker takes a run of subtrees: the corners of their faces gathered from
the points into the copy and into the leaves, then their binary nodes bottom up from
the copy, then their wide nodes' boxes from the binary nodes) and one thread for the
few nodes above the cut: each array is written once, by the thread that has the
values it needs in its cache (docs/performance.md, "CPU refit and build, session 12").
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

from kdsl.frontend.api import atomic_add, func, kernel, static, thread_fence, tid
from kdsl.frontend.builtins_prefetch import PREFETCH as prefetch
from kdsl.frontend.constants import nan
from kdsl.geometry.bvh import Bvh
from kdsl.geometry.device_tree import any_set
from kdsl.geometry.finite_minmax import high3, low3
from kdsl.geometry.mesh_tree_points import TreePoints
from kdsl.geometry.wide_collapse import LANES, WORKERS, Collapsed, collapse
from kdsl.runtime.alloc import empty
from kdsl.runtime.array import array
from kdsl.runtime.graphs import state as graphs
from kdsl.runtime.launch import launch
from kdsl.runtime.objects import ObjectRecord
from kdsl.stdlib.bvh import BvhNode
from kdsl.stdlib.mesh_primitives import is_sliver
from kdsl.stdlib.mesh_wide import WideLeaf, WideNode, WideRecord
from kdsl.types import float32, int32, vec2i, vec3, vec4i

#: Whether a mesh keeps a 4-wide tree, per device kind (the one place this is chosen).
WIDE_TREE = {"cpu": True, "cuda": False}


@func
def lane_boxes(nd: WideNode, bnodes: array(dtype=BvhNode)) -> WideNode:
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


@func
def leaf_from_tri(tri: array(dtype=vec3), items: array(dtype=int32), span: vec2i) -> WideLeaf:
    """The wide leaf of the faces at item positions ``span[0] .. span[0] + span[1] - 1``:
    their corners, read from the mesh's vertex copy in item order (consecutive: no index
    loads; zero in an empty lane), and the faces' numbers (-1 for an empty lane or a
    sliver)."""
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
    return lf


@func
def _wide_node(
    child: array(dtype=vec4i), src: array(dtype=vec4i), w: int, bnodes: array(dtype=BvhNode),
    nodes: array(dtype=WideNode), build: bool,
):  # fmt: skip
    """Wide node ``w``'s children's boxes from their binary nodes; after a build
    (``build``) its links too, from the collapse's ``child`` and ``src``."""
    nd = WideNode()
    if build:
        nd.child = child[w]
        nd.src = src[w]
    else:
        nd = nodes[w]
    nodes[w] = lane_boxes(nd, bnodes)


@func
def _gather_corners(
    points: array(dtype=vec3), indices: array(dtype=int32), items: array(dtype=int32),
    span: vec2i, tri: array(dtype=vec3),
):  # fmt: skip
    """Copy the corners of the faces at item positions ``span`` into the vertex copy
    (the indices were checked before)."""
    last = items.shape[0] - 1
    for i in range(span[1]):
        at = span[0] + i
        prefetch(indices, items[min(at + _AHEAD, last)] * 3)  # (faces in item order: misses)
        f = items[at] * 3
        tri[at * 3] = points[indices[f]]
        tri[at * 3 + 1] = points[indices[f + 1]]
        tri[at * 3 + 2] = points[indices[f + 2]]


@func
def _refit_binary(n: int, tri: array(dtype=vec3), bnodes: array(dtype=BvhNode)):
    """Binary node ``n``'s bounds: a leaf's from its faces' corners in the vertex copy,
    an inner node's from its two children's (written before); its links stay as they
    are."""
    nd = bnodes[n]
    lo = vec3()
    hi = vec3()
    if nd.first >= 0:  # (at most LANES faces: unrolled)
        at = nd.first * 3
        lo = tri[at]
        hi = lo
        for i in range(static(LANES)):
            if i < nd.next:
                for j in range(static(3)):
                    p = tri[at + i * 3 + j]
                    lo = low3(lo, p)
                    hi = high3(hi, p)
    else:
        a = bnodes[n + 1]
        right = n + 2  # (after a leaf on the left)
        if a.first < 0:
            right = a.next
        b = bnodes[right]
        lo = low3(a.lower, b.lower)
        hi = high3(a.upper, b.upper)
    nd.lower = lo
    nd.upper = hi
    bnodes[n] = nd


#: How far ahead (faces, nodes) the pass prefetches what it will read.
_AHEAD = 16
#: ``_refit_tasks``' modes: a build's first fill (the vertex copy gathered from the
#: points, the leaves, the wide nodes' links and boxes) and a refit (the copy, the
#: leaves, the binary tree's bounds and the wide nodes' boxes).
_BUILD, _REFIT = 0, 1


@func
def _above_cut(
    tops: array(dtype=int32), top_wide: array(dtype=int32), mode: int32,
    child: array(dtype=vec4i), src: array(dtype=vec4i), tri: array(dtype=vec3),
    bnodes: array(dtype=BvhNode), nodes: array(dtype=WideNode),
):  # fmt: skip
    """The nodes above the cut, after every task: with ``_REFIT`` the binary ones
    (listed parents first: taken in reverse), then the wide ones."""
    if mode == _REFIT:
        for m in range(tops.shape[0]):
            _refit_binary(tops[tops.shape[0] - 1 - m], tri, bnodes)
    for m in range(top_wide.shape[0]):
        _wide_node(child, src, top_wide[m], bnodes, nodes, mode == _BUILD)


@kernel
def _refit_tasks(
    points: array(dtype=vec3), indices: array(dtype=int32), items: array(dtype=int32),
    spans: array(dtype=vec2i), tasks: array(dtype=vec4i), trees: array(dtype=vec4i),
    workers: array(dtype=int32), tops: array(dtype=int32), top_wide: array(dtype=int32),
    found: array(dtype=int32), done: array(dtype=int32), mode: int32,
    child: array(dtype=vec4i), src: array(dtype=vec4i), tri: array(dtype=vec3),
    bnodes: array(dtype=BvhNode), nodes: array(dtype=WideNode), leaves: array(dtype=WideLeaf),
):  # fmt: skip
    # Worker k: its run of tasks (``kdsl.geometry.wide_collapse``), each a subtree:
    # its faces' corners into the vertex copy, its leaves, with ``_REFIT`` its binary
    # nodes (reverse preorder: children first), then its wide nodes (``_wide_node``;
    # after a build with the collapse's links ``child`` and ``src``). The last worker
    # to finish (``done``: a counter, zero between launches) does the nodes above the
    # cut. Nothing when ``found`` (the mesh check's counters) has a count.
    k = tid()
    if any_set(found):
        return
    for t in range(workers[k], workers[k + 1]):
        tk = tasks[t]
        for leaf in range(tk[2], tk[3]):
            span = spans[leaf]
            _gather_corners(points, indices, items, span, tri)
            leaves[leaf] = leaf_from_tri(tri, items, span)
        if mode == _REFIT:
            tr = trees[t]
            for m in range(tr[1] - tr[0]):
                n = tr[1] - 1 - m
                prefetch(bnodes, max(n - _AHEAD, 0))  # (backwards: ahead of the prefetchers)
                _refit_binary(n, tri, bnodes)
        for w in range(tk[0], tk[1]):
            _wide_node(child, src, w, bnodes, nodes, mode == _BUILD)
    thread_fence()  # (this worker's writes before its arrival)
    if atomic_add(done, 0, 1) == WORKERS - 1:
        thread_fence()  # (every worker's writes seen)
        done[0] = 0
        _above_cut(tops, top_wide, mode, child, src, tri, bnodes, nodes)


def wants_wide_tree(device: Any, leaf_size: int) -> bool:
    """Whether a mesh on ``device`` whose BVH has leaves of at most ``leaf_size`` faces
    keeps a 4-wide tree (``WIDE_TREE``; never for leaves wider than a wide leaf)."""
    return WIDE_TREE["cuda" if device.is_cuda else "cpu"] and leaf_size <= LANES


class WideTree:
    """A mesh's 4-wide tree (``kdsl.stdlib.mesh_wide.WideRecord``; ``id`` for the mesh's
    record). ``tree_points`` is the mesh's ``TreePoints``: its vertex copy (``tri``, in
    the BVH's item order), which ``rebuild`` and ``refit`` write with the wide tree,
    what it is copied from (``points``, ``indices``) and the mesh check's counters
    (``found``). ``rebuild(bvh)`` collapses the binary tree again (after it was built);
    ``refit(bvh)`` updates the copy, ``bvh``'s bounds and the wide tree from the current
    points."""

    def __init__(self, tree_points: TreePoints, device: Any) -> None:
        self.tree_points = tree_points
        self.device = device
        self._record = ObjectRecord(self, WideRecord.__kdsl_type__, "mesh wide tree", device)
        self.nodes: array | None = None
        self.leaves: array | None = None
        self._spans: array | None = None
        self._cut: Collapsed | None = None
        #: (the arrays they were prepared for, the prepared refit launches).
        self._held: tuple | None = None

    @property
    def id(self) -> int:
        """The record's id (a ``uint64``), for ``MeshRecord.wide``."""
        return self._record.id

    def rebuild(self, bvh: Bvh) -> None:
        """Collapse ``bvh``'s tree (current bounds, items in their new order), gather the
        vertex copy from the points, fill the leaves and write the wide nodes
        (``TreePoints.write`` writes the copy instead when the collapse refused or there
        are no faces)."""
        dev = self.device
        tris = self.tree_points.indices.shape[0] // 3
        cut = collapse(bvh.packed_nodes, tris, dev)
        self.nodes = empty(cut.child.shape[0], dtype=WideNode, device=dev)
        self.leaves = empty(cut.spans.shape[0], dtype=WideLeaf, device=dev)
        self._spans = cut.spans
        self._cut = cut
        self._held = None
        if self.nodes.shape[0]:
            launch(_refit_tasks, dim=WORKERS, device=dev,
                   inputs=self._inputs(bvh, _BUILD, cut.child, cut.src))  # fmt: skip
        else:
            self.tree_points.write()
        cut.child = cut.src = None  # (the collapse's scratch: not kept)
        self._record.write({"nodes": self.nodes, "leaves": self.leaves, "fallback": cut.status})

    def refit(self, bvh: Bvh) -> None:
        """Copy the faces' corners from the current points into the vertex copy, refit
        ``bvh``'s bounds (links untouched) and the wide tree's boxes and leaves, in one
        launch; nothing is written when the mesh check's counters are set.
        A wide tree the collapse refused (or of no faces) leaves the tree to
        ``bvh.refit_checked`` and the copy to ``TreePoints.write``."""
        if not self.nodes.shape[0]:
            bvh.refit_checked(self.tree_points.found)
            self.tree_points.write()
            return
        for step in self._refit_steps(bvh):
            step()

    def _inputs(self, bvh: Bvh, mode: int, child: array, src: array) -> list:
        """``_refit_tasks``' arguments for a pass in ``mode``."""
        tp, cut = self.tree_points, self._cut
        return [tp.points, tp.indices, bvh.item_order, self._spans, cut.tasks, cut.trees,
                cut.workers, cut.tops, cut.top_wide, tp.found, cut.done, mode, child, src,
                tp.tri, bvh.packed_nodes, self.nodes, self.leaves]  # fmt: skip

    def _refit_steps(self, bvh: Bvh) -> list[Callable[[], object]]:
        """The refit's launch, prepared once per set of arrays; a plain launch while a
        graph capture is open (it records that)."""
        tp, dev = self.tree_points, self.device
        key = (tp.points, tp.indices, bvh.item_order, bvh.packed_nodes, tp.tri)
        held = self._held
        if not graphs.ACTIVE and held is not None and all(a is b for a, b in zip(held[0], key)):
            return held[1]
        no_links = self._cut.tasks[:0]  # (a refit keeps the nodes' links)
        inputs = self._inputs(bvh, _REFIT, no_links, no_links)
        if graphs.ACTIVE:
            return [functools.partial(launch, _refit_tasks, dim=WORKERS, device=dev,
                                      inputs=inputs)]  # fmt: skip
        steps = [launch(_refit_tasks, dim=WORKERS, device=dev, inputs=inputs,
                        record_cmd=True).launch]  # fmt: skip
        self._held = (key, steps)
        return steps
