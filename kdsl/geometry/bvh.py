"""``kdsl.Bvh``: a bounding volume hierarchy over boxes, queried from kernels by its id.

The tree lives on the boxes' device as plain arrays (see ``kdsl.stdlib.bvh`` for the
layout and the queries); its record (``kdsl.runtime.objects``) points kernels at them.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from kdsl.errors import KdslTypeError
from kdsl.geometry.median import Tree, build_median, refit_bounds
from kdsl.ir import types as T
from kdsl.runtime.array import array
from kdsl.runtime.objects import ObjectRecord
from kdsl.stdlib.bvh import BvhRecord
from kdsl.types import type_of

VEC3 = T.VectorType(3, T.F32)

#: The constructors by name; each builds a ``Tree`` from host boxes.
CONSTRUCTORS = {"median": build_median}


def _check_boxes(lowers: Any, uppers: Any) -> None:
    for name, a in (("lowers", lowers), ("uppers", uppers)):
        if not isinstance(a, array) or type_of(a.dtype) != VEC3 or a.ndim != 1:
            raise KdslTypeError(f"Bvh {name} must be a 1-d kdsl.array of vec3, not {a!r}")
    if lowers.shape != uppers.shape:
        raise KdslTypeError(
            f"Bvh lowers and uppers differ in length: {lowers.shape} and {uppers.shape}"
        )
    if lowers.device != uppers.device:
        raise KdslTypeError(
            f"Bvh lowers and uppers are on different devices: {lowers.device} and {uppers.device}"
        )


class Bvh:
    """A BVH over the boxes ``[lowers[i], uppers[i]]`` (vec3 arrays on one device), as
    ``warp.Bvh``. Pass ``bvh.id`` to kernels and query it with ``bvh_query_aabb``,
    ``bvh_query_ray``, ``bvh_query_sphere`` or ``bvh_query_capsule``. ``groups`` (int32
    per item) builds each group as a subtree (``bvh_get_group_root``). After changing the
    boxes, ``refit()`` updates the bounds; ``rebuild()`` builds the tree again."""

    def __init__(
        self,
        lowers: array,
        uppers: array,
        constructor: str | None = None,
        groups: array | None = None,
        leaf_size: int = 1,
    ) -> None:
        _check_boxes(lowers, uppers)
        self.lowers, self.uppers = lowers, uppers
        self.device = lowers.device
        self.groups = groups
        self.leaf_size = int(leaf_size)
        self.constructor = _constructor(constructor)
        self._record = ObjectRecord(self, BvhRecord.__kdsl_type__, "bvh", self.device)
        self._tree: Tree | None = None
        self.rebuild()

    @property
    def id(self) -> int:
        """The BVH's id (a ``uint64``) for kernels."""
        return self._record.id

    def rebuild(self, constructor: str | None = None) -> None:
        """Build the tree again from the current boxes (optionally with another constructor)."""
        if constructor is not None:
            self.constructor = _constructor(constructor)
        groups = None if self.groups is None else self.groups.numpy()
        lo, hi = self.lowers.numpy(), self.uppers.numpy()
        self._tree = CONSTRUCTORS[self.constructor](lo, hi, self.leaf_size, groups)
        tree = self._tree
        self._topology = {
            name: array(getattr(tree, name), dtype=T.I32, device=self.device)
            for name in ("skip", "first", "count", "items", "group_roots")
        }
        self._bounds = [
            array(np.zeros((tree.num_nodes, 3), np.float32), dtype=VEC3, device=self.device)
            for _ in range(2)
        ]
        self.refit()

    def refit(self) -> None:
        """Recompute the node bounds from the current boxes (the tree keeps its shape)."""
        lo, hi = refit_bounds(self._tree, self.lowers.numpy(), self.uppers.numpy())
        self._bounds[0].assign(lo)
        self._bounds[1].assign(hi)
        self._record.write(
            {
                "lowers": self._bounds[0], "uppers": self._bounds[1],
                **self._topology,
                "item_lowers": self.lowers, "item_uppers": self.uppers,
                "root": 0 if self._tree.num_nodes else -1,
            }
        )  # fmt: skip


def _constructor(name: str | None) -> str:
    name = name or "median"
    if name not in CONSTRUCTORS:
        raise KdslTypeError(
            f"unknown BVH constructor {name!r}; choose one of {sorted(CONSTRUCTORS)}"
        )
    return name
