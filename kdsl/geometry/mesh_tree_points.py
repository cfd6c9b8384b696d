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

A mesh's ``refit()`` writes the copy and the BVH's bounds in one pass
(``MeshBvh.refit_points``): a thread per leaf reads its faces' corners once, in item
order, writes them to the copy and bounds the leaf with them (the union of the faces'
boxes, in the order ``device_tree``'s leaves take them: the same bits), then climbs
(``device_tree.store_leaf``) on a GPU; on a CPU one thread then walks the inner nodes. It
reads the mesh check's answers on the device and writes nothing when the check found
a bad index or point, so the host need not wait for the check before issuing it.
"""

from __future__ import annotations

from kdsl.frontend.api import func, inout, kernel, tid
from kdsl.frontend.api import max as vmax
from kdsl.frontend.api import min as vmin
from kdsl.geometry.bvh import Bvh
from kdsl.geometry.device_tree import DeviceTree, refit_inner, store_leaf
from kdsl.runtime.array import array
from kdsl.runtime.launch import launch
from kdsl.runtime.stream import current_stream
from kdsl.types import int32, vec3


@kernel
def _gather_tree_points(
    points: array(dtype=vec3), indices: array(dtype=int32), items: array(dtype=int32),
    tri: array(dtype=vec3),
):  # fmt: skip
    # Thread k copies the corners of face items[k] to tri[3k .. 3k + 2]. The indices
    # were checked (in range) by the mesh's face-box kernel before any gather.
    k = tid()
    f = items[k]
    for j in range(3):
        tri[k * 3 + j] = points[indices[f * 3 + j]]


@func
def _copy_leaf(
    f: int, count: int, items: array(dtype=int32), points: array(dtype=vec3),
    indices: array(dtype=int32), tri: array(dtype=vec3), lo: inout(vec3), hi: inout(vec3),
):  # fmt: skip
    """Copy the corners of the faces ``items[f : f + count]`` to ``tri[3 f ..]`` and
    bound them into ``lo``/``hi`` (each face's box as the mesh check computes it, then
    their union in item order, as ``device_tree``'s leaves take their items' boxes)."""
    for j in range(f, f + count):
        k = items[j]
        a = points[indices[k * 3]]
        b = points[indices[k * 3 + 1]]
        c = points[indices[k * 3 + 2]]
        tri[j * 3] = a
        tri[j * 3 + 1] = b
        tri[j * 3 + 2] = c
        box_lo = vmin(vmin(a, b), c)
        box_hi = vmax(vmax(a, b), c)
        if j == f:
            lo = box_lo
            hi = box_hi
        else:
            lo = vmin(lo, box_lo)
            hi = vmax(hi, box_hi)


@func
def _found_bad(found: array(dtype=int32)) -> bool:
    """Whether the mesh check's two counters (``FaceBoxes.found``) found something."""
    return found[0] != 0 or found[1] != 0


@kernel
def _refit_points(
    first: array(dtype=int32), count: array(dtype=int32), items: array(dtype=int32),
    points: array(dtype=vec3), indices: array(dtype=int32), tri: array(dtype=vec3),
    found: array(dtype=int32), skip: array(dtype=int32), parent: array(dtype=int32),
    arrivals: array(dtype=int32), lowers: array(dtype=vec3), uppers: array(dtype=vec3),
):  # fmt: skip
    # Thread n: leaf n's corners copied and bounded, then (with parents) the climb.
    n = tid()
    f = first[n]
    if f < 0 or _found_bad(found):
        return
    lo = vec3()
    hi = vec3()
    _copy_leaf(f, count[n], items, points, indices, tri, lo, hi)
    store_leaf(n, lo, hi, skip, parent, arrivals, lowers, uppers)


def _stream_of(device) -> object:
    return None if device.is_cpu else current_stream(device)


def _same(a: tuple, b: tuple) -> bool:
    return all(x is y for x, y in zip(a, b))


class TreePoints:
    """The copy (``tri``: ``3 * faces`` vec3 on the mesh's device) and what it is copied
    from: ``points`` (the mesh's current points array; ``Mesh`` sets it when the points
    array is replaced), ``indices`` (both set by ``attach``) and the BVH's item order
    (``items``, set once the BVH exists). A mesh's ``FaceBoxes`` make one and it comes
    back with them when they are recycled; its launches are prepared once per set of
    arrays and stream, so a fresh mesh over the arrays of a collected one (its build
    recycled too) prepares none."""

    def __init__(self, tri: array) -> None:
        self.tri = tri
        self.points: array | None = None
        self.indices: array | None = None
        self.items: array | None = None
        self._gather: tuple | None = None  # (its arrays and stream, the prepared gather)
        self._refit: tuple | None = None  # (its arrays and stream, the prepared refit steps)

    def attach(self, points: array, indices: array) -> None:
        """Copy from ``points`` and ``indices`` (a new mesh's) from now on."""
        self.points, self.indices, self.items = points, indices, None

    def write(self) -> None:
        """Copy every face's corners in the BVH's item order (one launch)."""
        items = self.items
        if items is None or items.shape[0] == 0:
            return
        device = self.tri.device
        key = (self.points, self.indices, items, _stream_of(device))
        held = self._gather
        if held is None or not _same(held[0], key):
            gather = launch(
                _gather_tree_points, dim=items.shape[0], device=device, record_cmd=True,
                inputs=[self.points, self.indices, items, self.tri],
            ).launch  # fmt: skip
            held = self._gather = (key, gather)
        held[1]()

    def refit(self, tree: DeviceTree, lowers: array, uppers: array, found: array) -> None:
        """Write the copy and ``tree``'s node bounds (``lowers``/``uppers``) from the
        points, in one pass over the leaves (see the module docstring); nothing is
        written when the mesh check's counters ``found`` are not zero."""
        if tree.slots == 0:
            return
        device = self.tri.device
        key = (tree.first, tree.items, lowers, self.points, self.indices, found,
               _stream_of(device))  # fmt: skip
        held = self._refit
        if held is None or not _same(held[0], key):
            steps = [launch(
                _refit_points, dim=tree.slots, device=device, record_cmd=True,
                inputs=[tree.first, tree.count, tree.items, self.points, self.indices,
                        self.tri, found, tree.skip, tree.parent, tree.arrivals, lowers, uppers],
            ).launch]  # fmt: skip
            if tree.parent.shape[0] == 0:  # no parent links (a CPU's tree): the inner nodes
                steps.append(refit_inner(tree, lowers, uppers, record_cmd=True))
            held = self._refit = (key, steps)
        for step in held[1]:
            step()


class MeshBvh(Bvh):
    """A mesh's BVH: a ``kdsl.Bvh`` that also rewrites the mesh's ``TreePoints`` after
    each ``rebuild()`` (the items' order changes), and refits from the mesh's points
    (``refit_points``). It holds the copy, not the mesh, so a BVH the user keeps does
    not keep its mesh alive."""

    tree_points: TreePoints | None = None
    #: The mesh's 4-wide tree (``kdsl.geometry.wide_tree.WideTree``), if it keeps one.
    wide = None

    def rebuild(self, constructor: str | None = None) -> None:
        """``Bvh.rebuild``, then the mesh's vertex copy in the new item order."""
        super().rebuild(constructor)
        if self.tree_points is not None:
            self.tree_points.items = self.item_order
            self.tree_points.write()
        if self.wide is not None:
            self.wide.rebuild(self)

    def refit_points(self, found: array) -> None:
        """Refit the bounds from the mesh's points and write its vertex copy, in one
        pass over the leaves (``TreePoints.refit``); nothing is written when the mesh
        check's counters ``found`` are not zero."""
        if self.tree_points is not None:
            self.tree_points.refit(self._tree, self._bounds[0], self._bounds[1], found)
