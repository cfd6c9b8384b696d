"""``kdsl.Bvh``: a bounding volume hierarchy over boxes, queried from kernels by its id.

The tree lives on the boxes' device as plain arrays (see ``kdsl.stdlib.bvh`` for the
layout and the queries); its record (``kdsl.runtime.objects``) points kernels at them.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from kdsl.errors import KdslError, KdslTypeError
from kdsl.geometry.device_tree import DeviceTree, node_views, pack_nodes, refit_steps, upload_tree
from kdsl.geometry.lbvh import build_lbvh
from kdsl.geometry.median import build_median
from kdsl.geometry.sah import build_sah
from kdsl.ir import types as T
from kdsl.runtime.alloc import empty, zeros
from kdsl.runtime.array import array
from kdsl.runtime.graphs import state as graphs
from kdsl.runtime.objects import ObjectRecord
from kdsl.runtime.stream import current_stream
from kdsl.stdlib.bvh import BvhNode, BvhRecord
from kdsl.types import int32

VEC3 = T.VectorType(3, T.F32)


class BvhError(KdslError, RuntimeError):
    """A bad ``Bvh`` argument value (a ``RuntimeError`` too, as Warp's Bvh errors are)."""


def _host_build(build):
    """A host constructor (``Tree`` from NumPy boxes) as a ``DeviceTree`` constructor."""

    def construct(lowers, uppers, leaf_size, groups, num_groups) -> DeviceTree:
        g = None if groups is None else groups.numpy()
        tree = build(lowers.numpy(), uppers.numpy(), leaf_size, g, num_groups)
        return upload_tree(tree, lowers.device)

    return construct


#: The constructors by name: each builds a ``DeviceTree`` from the boxes.
CONSTRUCTORS = {
    "lbvh": build_lbvh,
    "median": _host_build(build_median),
    "sah": _host_build(build_sah),
}


def _check_boxes(lowers: Any, uppers: Any) -> None:
    for name, a in (("lowers", lowers), ("uppers", uppers)):
        if not isinstance(a, array) or a.__kdsl_type__.dtype != VEC3 or a.ndim != 1:
            raise KdslTypeError(f"Bvh {name} must be a 1-d kdsl.array of vec3, not {a!r}")
    if lowers.shape != uppers.shape:
        raise KdslTypeError(
            f"Bvh lowers and uppers differ in length: {lowers.shape} and {uppers.shape}"
        )
    if lowers.device != uppers.device:
        raise KdslTypeError(
            f"Bvh lowers and uppers are on different devices: {lowers.device} and {uppers.device}"
        )


def _check_groups(groups: Any, lowers: array) -> int:
    """Check ``groups`` against the boxes; the number of groups (0 without groups)."""
    if groups is None:
        return 0
    if not isinstance(groups, array) or groups.__kdsl_type__.dtype != T.I32 or groups.ndim != 1:
        raise KdslTypeError(f"Bvh groups must be a 1-d kdsl.array of int32, not {groups!r}")
    if groups.shape != lowers.shape:
        raise KdslTypeError(f"Bvh groups has {groups.shape[0]} entries for {lowers.shape[0]} boxes")
    if groups.device != lowers.device:
        raise KdslTypeError(f"Bvh groups is on {groups.device}, the boxes on {lowers.device}")
    g = groups.numpy()  # one read (of ints) per build, for the number of groups
    if len(g) and int(g.min()) < 0:
        raise BvhError(f"Bvh groups must be >= 0, found {int(g.min())}")
    return int(g.max()) + 1 if len(g) else 0


class Bvh:
    """A BVH over the boxes ``[lowers[i], uppers[i]]`` (vec3 arrays on one device), as
    ``warp.Bvh``. Pass ``bvh.id`` to kernels and query it with ``bvh_query_aabb``,
    ``bvh_query_ray``, ``bvh_query_sphere`` or ``bvh_query_capsule``. ``groups`` (int32
    per item, >= 0) builds each group as a subtree (``bvh_get_group_root``).
    ``constructor`` is ``"lbvh"``, ``"median"``, ``"sah"`` or None (the device's
    default, ``DEFAULT_CONSTRUCTOR``); ``leaf_size`` is the most items a leaf holds.
    After changing the boxes, ``refit()`` updates the bounds; ``rebuild()`` builds the
    tree again."""

    def __init__(
        self,
        lowers: array,
        uppers: array,
        constructor: str | None = None,
        groups: array | None = None,
        leaf_size: int = 1,
    ) -> None:
        _check_boxes(lowers, uppers)
        if isinstance(leaf_size, bool) or not isinstance(leaf_size, int | np.integer):
            raise KdslTypeError(f"Bvh leaf_size must be an int, not {leaf_size!r}")
        if leaf_size < 1:
            raise BvhError(f"Bvh leaf_size must be at least 1, not {leaf_size}")
        self.lowers, self.uppers = lowers, uppers
        self.device = lowers.device
        self._num_groups = _check_groups(groups, lowers)
        self.groups = groups
        self.leaf_size = int(leaf_size)
        self.constructor = _constructor(constructor, self.device)
        self._record = ObjectRecord(self, BvhRecord.__kdsl_type__, "bvh", self.device)
        #: (what they were prepared for, the prepared refit launches): ``_refit_steps``.
        self._refit_held: tuple | None = None
        self.rebuild()

    @property
    def id(self) -> int:
        """The BVH's id (a ``uint64``) for kernels."""
        return self._record.id

    @property
    def item_order(self) -> array:
        """The items in tree order (int32, one per item): a leaf holds those at positions
        ``first .. first + count - 1`` (``kdsl.stdlib.bvh``). A ``rebuild()`` may reorder
        them (and replace the array)."""
        return self._tree.items

    @property
    def packed_nodes(self) -> array:
        """The packed nodes (``kdsl.stdlib.bvh.BvhNode``, one per slot) kernels walk: a
        leaf's ``first`` is its first item position, an inner node's is ``-1 - right``
        (its right child; the left one is the next node); a ``rebuild()`` may replace
        the array."""
        return self._nodes

    def rebuild(self, constructor: str | None = None) -> None:
        """Build the tree again from the current boxes (optionally with another constructor)."""
        if constructor is not None:
            self.constructor = _constructor(constructor, self.device)
        self._check_current_boxes()
        if self.groups is not None:
            self._num_groups = _check_groups(self.groups, self.lowers)
        shape = (self.constructor, self.lowers, self.uppers, self.groups, self._num_groups)
        tree = getattr(self, "_tree", None)
        same = tree is not None and all(a is b for a, b in zip(shape, self._built))
        if same and tree.rebuild is not None:
            tree.rebuild()  # the same buffers and prepared launches; the record holds
            return
        build = CONSTRUCTORS[self.constructor]
        tree = build(self.lowers, self.uppers, self.leaf_size, self.groups, self._num_groups)
        self._tree, self._built = tree, shape
        if tree.nodes is not None:  # the constructor packed the links itself
            self._nodes = tree.nodes
            self._views = tree.views if tree.views is not None else node_views(tree.nodes)
        else:
            self._nodes = empty(tree.slots, dtype=BvhNode, device=self.device)
            self._views = node_views(self._nodes)
            pack_nodes(tree, self._views)
        self._bounds = [self._views[0], self._views[2]]
        if not tree.bounded:
            for step in self._refit_steps():
                step()
        self._write_record()

    def _check_current_boxes(self) -> None:
        """Check ``lowers``/``uppers`` again: a user may have assigned new arrays."""
        _check_boxes(self.lowers, self.uppers)
        if self.lowers.device != self.device:
            raise KdslTypeError(
                f"Bvh boxes moved to {self.lowers.device}; the BVH lives on {self.device}"
            )

    def _write_record(self) -> None:
        tree = self._tree
        self._recorded = (self.lowers, self.uppers)
        self._record.write(
            {
                "lowers": self._bounds[0], "uppers": self._bounds[1],
                "skip": tree.skip, "first": self._views[1], "count": tree.count,
                "items": tree.items, "group_roots": tree.group_roots,
                "item_lowers": self.lowers, "item_uppers": self.uppers,
                "root": 0 if tree.slots else -1, "nodes": self._nodes,
                "nodes_ptr": _address(self._nodes), "items_ptr": _address(tree.items),
                "height": tree.height if tree.height is not None else self._zero_height(),
            }
        )  # fmt: skip

    def _zero_height(self) -> array:
        """A one-element zero on the device: the height of an empty tree."""
        return zeros(1, dtype=int32, device=self.device)

    def refit(self) -> None:
        """Recompute the node bounds from the current boxes (the tree keeps its shape), with
        kernels on the BVH's device."""
        if self._recorded[0] is not self.lowers or self._recorded[1] is not self.uppers:
            self._check_current_boxes()  # new box arrays: same count, then a new record
            if self.lowers.shape[0] != self._recorded[0].shape[0]:
                raise BvhError(
                    f"refit needs as many boxes as the BVH was built over "
                    f"({self._recorded[0].shape[0]}, now {self.lowers.shape[0]}); call rebuild()"
                )
            self._write_record()
        for step in self._refit_steps():
            step()

    def _refit_steps(self, found: array | None = None) -> list:
        """The refit's launches (``device_tree.refit_steps``), prepared once per tree, box
        arrays, ``found`` and stream; plain launches while a graph capture is open (it
        records those)."""
        if graphs.ACTIVE:
            return refit_steps(self._tree, self.lowers, self.uppers, self._nodes, found,
                               prepared=False)  # fmt: skip
        stream = None if self.device.is_cpu else current_stream(self.device)
        key = (self._tree, self._nodes, self.lowers, self.uppers, found, stream)
        held = self._refit_held
        if held is None or any(a is not b for a, b in zip(held[0], key)):
            steps = refit_steps(self._tree, self.lowers, self.uppers, self._nodes, found)
            held = self._refit_held = (key, steps)
        return held[1]


def _address(a: array) -> int:
    """The address of contiguous array ``a``'s first element (0 when empty), for a
    record's ``*_ptr`` fields (``kdsl.stdlib.bvh.packed_nodes``)."""
    if a.shape[0] == 0:
        return 0
    if not a.is_contiguous:
        raise BvhError(f"internal error: a BVH array the walks read by address is strided: {a!r}")
    return a.ptr


#: The constructor a BVH gets without ``constructor=``, per device kind: the one that
#: measured fastest to build plus query (docs/performance.md, "Geometry").
DEFAULT_CONSTRUCTOR = {"cpu": "lbvh", "cuda": "lbvh"}


def _constructor(name: str | None, device: Any) -> str:
    if name is None:
        return DEFAULT_CONSTRUCTOR["cuda" if device.is_cuda else "cpu"]
    if name not in CONSTRUCTORS:
        raise BvhError(f"unknown BVH constructor {name!r}; choose one of {sorted(CONSTRUCTORS)}")
    return name
