"""``kdsl.Mesh``: a triangle mesh queried from kernels by its id (Warp's ``warp.Mesh``).

The mesh keeps the user's arrays as they are (no copy when they are already a 1-d
vec3 array and contiguous int32 indices on one device); a ``kdsl.Bvh`` over the faces'
boxes accelerates the queries, and the mesh's record (``MeshRecord`` of
``kdsl.stdlib.mesh``) holds the arrays' descriptors and the BVH's id. Holding the id
rather than a copy of the BVH's arrays costs a kernel one more record read per query
(a few loads), and keeps one owner of the tree.
"""

from __future__ import annotations

from typing import Any

from kdsl.errors import KdslTypeError
from kdsl.geometry.mesh_refit import face_boxes, keep_face_boxes
from kdsl.geometry.mesh_tree_points import MeshBvh
from kdsl.geometry.wide_tree import WideTree, wants_wide_tree
from kdsl.ir import types as T
from kdsl.runtime.array import array
from kdsl.runtime.objects import ObjectRecord
from kdsl.stdlib.mesh import MeshRecord

VEC3 = T.VectorType(3, T.F32)


def _as_points(a: Any, name: str) -> array:
    """``a`` as a 1-d vec3 array: a vec3 array as it is, a float32 ``(n, 3)`` array
    viewed as vec3 (no copy when contiguous)."""
    if not isinstance(a, array):
        raise KdslTypeError(
            f"Mesh {name} must be a kdsl.array of vec3 (or float32 of shape (n, 3)), not "
            f"{type(a).__name__}; convert with kdsl.array(...), kdsl.from_torch(...) or "
            "kdsl.from_dlpack(...)"
        )
    t = a.__kdsl_type__.dtype  # (cheaper than type_of(a.dtype))
    if t == VEC3 and a.ndim == 1:
        return a
    if t == T.F32 and a.ndim == 2 and a.shape[1] == 3:
        return (a if a.is_contiguous else a.contiguous()).view(VEC3)
    raise KdslTypeError(
        f"Mesh {name} must be a 1-d array of vec3 or a float32 array of shape (n, 3), not "
        f"{a.dtype.__name__ if hasattr(a.dtype, '__name__') else a.dtype} of shape {a.shape}"
    )


def _as_indices(a: Any) -> array:
    """``a`` as a flat int32 array of ``3 * faces`` entries (an ``(m, 3)`` array is
    flattened, without a copy when contiguous)."""
    if not isinstance(a, array):
        raise KdslTypeError(f"Mesh indices must be a kdsl.array of int32, not {type(a).__name__}")
    if a.__kdsl_type__.dtype != T.I32:
        raise KdslTypeError(f"Mesh indices must be int32, not {a.dtype}")
    if a.ndim == 2:
        if a.shape[1] != 3:
            raise KdslTypeError(
                f"Mesh indices of shape {a.shape}: a 2-d index array must be (faces, 3)"
            )
        a = (a if a.is_contiguous else a.contiguous()).flatten()
    if a.ndim != 1:
        raise KdslTypeError(f"Mesh indices must be 1-d or (faces, 3), not of shape {a.shape}")
    if a.shape[0] % 3:
        raise KdslTypeError(
            f"Mesh indices hold {a.shape[0]} entries, not a multiple of 3 (three per triangle)"
        )
    return a


#: The most faces a BVH leaf holds when ``bvh_leaf_size`` is None (Warp's default).
DEFAULT_LEAF_SIZE = 4


class Mesh:
    """A triangle mesh, as ``warp.Mesh``: ``points`` (vec3 per vertex), ``indices``
    (three int32 per face, flat or ``(faces, 3)``), optional ``velocities``. Pass
    ``mesh.id`` to kernels and query it with ``mesh_query_point``, ``mesh_query_ray``
    and the other ``mesh_*`` functions. After moving the points (``mesh.points``, in
    place or assigned), call ``refit()``. ``groups`` (int32 per face) makes each group
    a subtree (``mesh_get_group_root``); ``bvh_constructor`` picks the BVH builder and
    ``bvh_leaf_size`` the most faces a leaf holds (None: 4, Warp's default: a point
    query then steps through a quarter of the nodes, for a few more triangle tests).
    The parameters are Warp 1.19's, in its order."""

    def __init__(
        self,
        points: array,
        indices: array,
        velocities: array | None = None,
        support_winding_number: bool = False,
        bvh_constructor: str | None = None,
        bvh_leaf_size: int | None = None,
        groups: array | None = None,
    ) -> None:
        pts = _as_points(points, "points")
        idx = _as_indices(indices)
        self.device = pts.device
        if idx.device != self.device:
            raise KdslTypeError(
                f"Mesh points and indices are on different devices: {self.device} and {idx.device}"
            )
        vel = None
        if velocities is not None:
            vel = _as_points(velocities, "velocities")
            if vel.device != self.device or vel.shape != pts.shape:
                raise KdslTypeError(
                    f"Mesh velocities must match the points ({pts.shape[0]} on {self.device}),"
                    f" not {vel.shape[0]} on {vel.device}"
                )
        num_tris = idx.shape[0] // 3
        if groups is not None and (not isinstance(groups, array) or groups.shape != (num_tris,)):
            raise KdslTypeError("Mesh groups must be an int32 array with one entry per face")
        self._points, self.indices, self.velocities = pts, idx, vel
        self.support_winding_number = bool(support_winding_number)
        self._num_tris = num_tris
        self._faces = face_boxes(num_tris, self.device)  # the checks write them
        self._recorded: tuple | None = None
        self._faces.start(pts, idx)  # the check, the boxes, the edge sum: answers below
        self.bvh = MeshBvh(
            self._faces.lowers, self._faces.uppers, constructor=bvh_constructor, groups=groups,
            leaf_size=DEFAULT_LEAF_SIZE if bvh_leaf_size is None else bvh_leaf_size,
        )  # fmt: skip
        self._raise_if_bad()  # (waits for the check, not for the BVH's build)
        self._tree_points = self._faces.tree_points  # the vertices in item order
        self._tree_points.attach(pts, idx)
        self.bvh.tree_points = self._tree_points  # (its rebuild() writes them again)
        self._tree_points.items = self.bvh.item_order
        self._wide = None  # the CPU's 4-wide tree for the closest points (wide_tree)
        if wants_wide_tree(self.device, self.bvh.leaf_size):
            self._wide = WideTree(self._tree_points, self.device)
            self._wide.rebuild(self.bvh)  # (it writes the vertex copy too)
            self.bvh.wide = self._wide  # (its rebuild() collapses the new tree)
        else:
            self._tree_points.write()
        keep_face_boxes(self.bvh, self._faces)  # for a later mesh, once the BVH is collected
        self._record = ObjectRecord(self, MeshRecord.__kdsl_type__, "mesh", self.device)
        self._write_record()

    @property
    def id(self) -> int:
        """The mesh's id (a ``uint64``) for kernels."""
        return self._record.id

    @property
    def points(self) -> array:
        """The vertex positions (vec3); after changing them, call ``refit()``."""
        return self._points

    @points.setter
    def points(self, value: array) -> None:
        pts = _as_points(value, "points")
        if pts.shape != self._points.shape or pts.device != self.device:
            raise KdslTypeError(
                f"new Mesh points must be {self._points.shape[0]} vec3 on {self.device}, not "
                f"{pts.shape[0]} on {pts.device}"
            )
        self._points = pts
        self._tree_points.points = pts
        self.refit()

    def refit(self) -> None:
        """Update the face boxes and the BVH's bounds from the current points (the tree
        keeps its shape: rebuild with ``mesh.bvh.rebuild()`` after large motions). An
        index out of range or a non-finite point is an error, and the BVH keeps its
        bounds and the vertex copy. The check, the edge sum, the BVH's refit and the
        copy's gather are issued before the host waits for the check's answers (the
        refit and the gather read them on the device); on a GPU the three run side by
        side behind the check, as one graph from the second refit on."""
        if self._wide is not None:
            self._refit_wide()
            return
        faces = self._faces
        gather = self._tree_points.prepared(faces.beside_stream())
        faces.start(self._points, self.indices, self.bvh.refit_checked_steps(faces.found),
                    () if gather is None else (gather,))  # fmt: skip
        self._raise_if_bad()
        self._write_record()

    def _refit_wide(self) -> None:
        """``refit()`` of a mesh that keeps a 4-wide tree (a CPU's, ``wide_tree``): the
        check, then one pass over the wide tree's subtrees that writes the vertex copy,
        the BVH's bounds and the wide tree (``WideTree.refit``: nothing when the check
        found something), then the wait for the check's answers."""
        self._faces.start(self._points, self.indices)
        self._wide.refit(self.bvh)
        self._raise_if_bad()
        self._write_record()

    def _raise_if_bad(self) -> None:
        """Wait for the answers of the check ``FaceBoxes.start`` issued; raise for a bad
        index or point."""
        bad_index, bad_point = self._faces.finish()
        if bad_index >= 0:
            value = int(self.indices[bad_index : bad_index + 1].numpy()[0])
            raise KdslTypeError(
                f"Mesh indices out of range: {value} for {self._points.shape[0]} points"
            )
        if bad_point >= 0:
            value = self._points[bad_point : bad_point + 1].numpy()[0].tolist()
            raise KdslTypeError(f"Mesh point {bad_point} is not finite: {value}")

    def _write_record(self) -> None:
        state = (self._points, self.velocities, self.bvh.id)
        if self._recorded is not None and all(a is b for a, b in zip(state, self._recorded)):
            return  # the same arrays: the record is current (the edge sum is on the device)
        self._recorded = state
        self._record.write(
            {
                "points": self._points,
                "velocities": self.velocities if self.velocities is not None
                else self._faces.none,
                "indices": self.indices, "bvh": self.bvh.id, "tri": self._tree_points.tri,
                "num_points": self._points.shape[0], "num_tris": self._num_tris,
                "edge_length_sum": self._faces.edge_sum,
                "support_winding_number": int(self.support_winding_number),
                "wide": 0 if self._wide is None else self._wide.id,
                "tri_ptr": self._tree_points.tri.ptr,  # (contiguous: one allocation)
            }
        )  # fmt: skip
