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
"""

from __future__ import annotations

from kdsl.frontend.api import kernel, tid
from kdsl.geometry.bvh import Bvh
from kdsl.runtime.alloc import empty
from kdsl.runtime.array import array
from kdsl.runtime.launch import launch
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


class TreePoints:
    """The copy (``tri``: ``3 * faces`` vec3 on the mesh's device) and what it is
    copied from: ``points`` (the mesh's current points array; ``Mesh`` sets it when
    the points array is replaced), ``indices`` and the BVH whose item order it
    follows (set once the BVH exists)."""

    def __init__(self, points: array, indices: array, num_tris: int) -> None:
        self.points, self.indices = points, indices
        self.tri = empty(3 * num_tris, dtype=vec3, device=points.device)
        self.items: array | None = None

    def write(self) -> None:
        """Copy every face's corners in the BVH's item order (one launch)."""
        items = self.items
        if items is None or items.shape[0] == 0:
            return
        launch(
            _gather_tree_points, dim=items.shape[0], device=self.points.device,
            inputs=[self.points, self.indices, items, self.tri],
        )  # fmt: skip


class MeshBvh(Bvh):
    """A mesh's BVH: a ``kdsl.Bvh`` that also rewrites the mesh's ``TreePoints`` after
    each ``rebuild()`` (the items' order changes). It holds the copy, not the mesh, so
    a BVH the user keeps does not keep its mesh alive."""

    tree_points: TreePoints | None = None

    def rebuild(self, constructor: str | None = None) -> None:
        """``Bvh.rebuild``, then the mesh's vertex copy in the new item order."""
        super().rebuild(constructor)
        if self.tree_points is not None:
            self.tree_points.items = self.item_order
            self.tree_points.write()
