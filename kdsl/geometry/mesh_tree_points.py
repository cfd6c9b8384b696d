"""A mesh's vertices copied in its BVH's item order, for the queries' leaf tests.

A leaf of a mesh's BVH holds the faces ``items[first : first + count]``; testing one
of them through the mesh's arrays takes three dependent loads (the item, its three
indices, then each vertex, from anywhere in ``points``). ``TreePoints`` keeps each
item position's triangle as three consecutive vec3 (``tri[3 k .. 3 k + 2]`` are the
corners of face ``items[k]``, in the face's index order): a leaf's triangles are then
``9 * count`` consecutive floats, read without the index loads, and a query loads the
face number ``items[k]`` only when that face would be its answer. It costs 36 bytes
a face (7.2 MB for 200k faces) and one gather launch after every build, rebuild and
refit; the walks in ``kdsl.stdlib.mesh`` read it through the mesh's record
(``MeshRecord.tri``).

The copy must follow the points and the tree: ``Mesh`` writes it at construction and
at every ``refit()`` (after the points moved, in place or by assigning
``mesh.points``), and the mesh's BVH (``MeshBvh``) writes it again after every
``rebuild()``, which reorders the items.

A ``refit()`` issues the gather behind the mesh's check (on a GPU on a side stream,
beside the BVH's refit: ``mesh_refit``), before the host has the check's answers: the
gather reads the check's counters on the device and leaves the copy as it was when
they are set. (Writing the copy in the check itself, in item order,
and in the BVH refit's leaf pass both measured slower on the H200: session 11,
docs/performance.md.)
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from kdsl.frontend.api import kernel, tid
from kdsl.geometry.bvh import Bvh
from kdsl.geometry.device_tree import any_set
from kdsl.runtime.array import array
from kdsl.runtime.graphs import state as graphs
from kdsl.runtime.launch import launch
from kdsl.runtime.stream import current_stream
from kdsl.types import int32, vec3


@kernel
def _gather_tree_points(
    points: array(dtype=vec3), indices: array(dtype=int32), items: array(dtype=int32),
    found: array(dtype=int32), tri: array(dtype=vec3),
):  # fmt: skip
    # Thread c copies corner c % 3 of face items[c // 3] to tri[c] (a thread a corner:
    # a warp's stores are 384 consecutive bytes; a thread a face, 36 bytes apart each,
    # took the H200 twice as long). The indices were checked (in range) by the mesh's
    # face-box kernel before any gather; when that check found something (``found``:
    # its counters), nothing is read or written.
    c = tid()
    f = items[c // 3]
    if any_set(found):
        return
    tri[c] = points[indices[f * 3 + c % 3]]


def _stream_of(device) -> object:
    return None if device.is_cpu else current_stream(device)


def _same(a: tuple, b: tuple) -> bool:
    return all(x is y for x, y in zip(a, b))


class TreePoints:
    """The copy (``tri``: ``3 * faces`` vec3 on the mesh's device), the mesh check's
    counters that guard its gather (``found``: ``FaceBoxes.found``) and what it is copied
    from: ``points`` (the mesh's current points array; ``Mesh`` sets it when the points
    array is replaced), ``indices`` (both set by ``attach``) and the BVH's item order
    (``items``, set once the BVH exists). A mesh's ``FaceBoxes`` make one and it comes
    back with them when they are recycled; its launches are prepared once per set of
    arrays and stream, so a fresh mesh over the arrays of a collected one (its build
    recycled too) prepares none."""

    def __init__(self, tri: array, found: array) -> None:
        self.tri, self.found = tri, found
        self.points: array | None = None
        self.indices: array | None = None
        self.items: array | None = None
        #: Per stream: (the arrays it copies, the gather prepared on that stream).
        self._gather: dict[Any, tuple] = {}

    def attach(self, points: array, indices: array) -> None:
        """Copy from ``points`` and ``indices`` (a new mesh's) from now on."""
        self.points, self.indices, self.items = points, indices, None

    def write(self) -> None:
        """Copy every face's corners in the BVH's item order (one launch); nothing when
        one of the mesh check's counters (``found``, on the device) is set."""
        items = self.items
        if items is None or items.shape[0] == 0:
            return
        if graphs.ACTIVE:  # a plain launch, which an open graph capture records
            launch(_gather_tree_points, dim=3 * items.shape[0], device=self.tri.device,
                   inputs=[self.points, self.indices, items, self.found, self.tri])  # fmt: skip
            return
        self.prepared()()

    def prepared(self, stream: Any = None) -> Callable[[], object] | None:
        """``write``'s launch prepared on ``stream`` (a ``kdsl.Stream``; None: the current
        one), once per set of arrays and stream (None with no items): a mesh's refit
        issues it beside the BVH's refit."""
        items = self.items
        if items is None or items.shape[0] == 0:
            return None
        device = self.tri.device
        if stream is None:
            stream = _stream_of(device)
        key = (self.points, self.indices, items)
        held = self._gather.get(stream)
        if held is None or not _same(held[0], key):
            inputs = [self.points, self.indices, items, self.found, self.tri]
            gather = launch(_gather_tree_points, dim=3 * items.shape[0], device=device,
                            inputs=inputs, record_cmd=True, stream=stream).launch  # fmt: skip
            held = self._gather[stream] = (key, gather)
        return held[1]


class MeshBvh(Bvh):
    """A mesh's BVH: a ``kdsl.Bvh`` that also rewrites the mesh's ``TreePoints`` after
    each ``rebuild()`` (the items' order changes), and refits under the mesh check's
    answers (``refit_checked``). It holds the copy, not the mesh, so a BVH the user keeps does
    not keep its mesh alive."""

    tree_points: TreePoints | None = None
    #: The mesh's 4-wide tree (``kdsl.geometry.wide_tree.WideTree``), if it keeps one.
    wide = None

    def rebuild(self, constructor: str | None = None) -> None:
        """``Bvh.rebuild``, then the mesh's vertex copy in the new item order (written by
        the wide tree's rebuild when the mesh keeps one)."""
        super().rebuild(constructor)
        if self.tree_points is not None:
            self.tree_points.items = self.item_order
            if self.wide is None:
                self.tree_points.write()
        if self.wide is not None:
            self.wide.rebuild(self)

    def refit_checked(self, found: array) -> None:
        """Refit the bounds from the current face boxes, on the device, unless the mesh
        check's counters ``found`` are set (then nothing is written): a mesh's refit
        issues it before the host has the check's answers."""
        for step in self.refit_checked_steps(found):
            step()

    def refit_checked_steps(self, found: array) -> list[Callable[[], object]]:
        """``refit_checked``'s launches, prepared (the same list while the tree, the boxes,
        ``found`` and the stream stay): a mesh's refit issues them in one graph."""
        return self._refit_steps(found)
