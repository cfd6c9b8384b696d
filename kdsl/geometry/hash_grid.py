"""``kdsl.HashGrid``: points bucketed into a wrapped grid of cells, queried from kernels.

The grid's tables are built on its device by ``kdsl.geometry.hash_grid_build`` (a sort
of unique keys: NumPy's sort on the CPU, the kdsl merge sort on a GPU; kdsl kernels, no
read back to the host, buffers kept between builds); the queries are kernel code in
``kdsl.stdlib.hash_grid``.
"""

from __future__ import annotations

import math
import operator
from typing import Any

import numpy as np

from kdsl.errors import KdslError, KdslTypeError
from kdsl.geometry.hash_grid_build import builder
from kdsl.ir import types as T
from kdsl.runtime.array import array
from kdsl.runtime.device import get_device
from kdsl.runtime.objects import ObjectRecord
from kdsl.stdlib.hash_grid import HashGridRecord
from kdsl.types import type_of

VEC3 = T.VectorType(3, T.F32)
#: The most buckets a grid may have: bucket indices are int32 (Warp's limit too).
MAX_CELLS = 2**31 - 1


class HashGridError(KdslError, ValueError, RuntimeError):
    """A bad ``HashGrid`` argument value (a ``ValueError`` and a ``RuntimeError`` too, the
    classes Warp raises for these)."""


def _dim(name: str, value: Any) -> int:
    if isinstance(value, bool):
        raise KdslTypeError(f"HashGrid {name} must be an int, not {value!r}")
    try:
        d = operator.index(value)
    except TypeError:
        raise KdslTypeError(f"HashGrid {name} must be an int, not {value!r}") from None
    if d <= 0:
        raise HashGridError(f"HashGrid {name} must be positive, not {d}")
    return d


def _cell_width_inv(radius: Any) -> np.float32:
    """``1 / radius`` in float32 (as Warp computes it), checked."""
    if isinstance(radius, bool) or not isinstance(radius, int | float | np.integer | np.floating):
        raise KdslTypeError(f"HashGrid.build radius must be a number, not {radius!r}")
    r = np.float32(radius)
    if not math.isfinite(float(radius)) or not radius > 0 or not r > 0:
        raise HashGridError(f"HashGrid.build radius must be positive and finite, not {radius!r}")
    with np.errstate(over="ignore"):
        inv = np.float32(1.0) / r
    if not np.isfinite(inv):
        raise HashGridError(f"HashGrid.build radius {radius!r} is too small: 1 / radius "
                            f"overflows float32")  # fmt: skip
    return inv


class HashGrid:
    """A hash grid of ``dim_x * dim_y * dim_z`` buckets on ``device``, as ``warp.HashGrid``.

    ``build(points, radius)`` buckets the points (a 1-d ``vec3`` array on the grid's
    device) into cells of width ``radius``; pass ``grid.id`` to kernels and query it
    with ``hash_grid_query`` / ``hash_grid_query_next``, and read the points in cell
    order with ``hash_grid_point_id``. Build again whenever the points move; builds of
    at most ``reserve``'s or a previous build's count reuse the buffers."""

    def __init__(self, dim_x: int, dim_y: int, dim_z: int, device: Any = None) -> None:
        self.dim_x, self.dim_y, self.dim_z = (
            _dim("dim_x", dim_x), _dim("dim_y", dim_y), _dim("dim_z", dim_z)
        )  # fmt: skip
        cells = self.dim_x * self.dim_y * self.dim_z
        if cells > MAX_CELLS:
            raise HashGridError(f"HashGrid has too many cells: {self.dim_x} * {self.dim_y} * "
                                f"{self.dim_z} = {cells} > {MAX_CELLS}")  # fmt: skip
        self.device = get_device(device)
        self.num_cells = cells
        self.num_points = 0
        self.radius: float | None = None
        self._builder = builder(self.device, (self.dim_x, self.dim_y, self.dim_z))
        self._radius_key: tuple | None = None
        self._inv = np.float32(0.0)
        self._record = ObjectRecord(self, HashGridRecord.__kdsl_type__, "hash_grid", self.device)
        self._recorded: tuple | None = None
        self._write_record(np.float32(0.0))

    @property
    def id(self) -> int:
        """The grid's id (a ``uint64``) for kernels."""
        return self._record.id

    @property
    def reserved(self) -> bool:
        """Whether the grid's point buffers are allocated (``reserve`` or ``build``)."""
        return self._builder.capacity >= 0

    def reserve(self, num_points: int) -> None:
        """Allocate the buffers for builds of up to ``num_points`` points now, so those
        builds (a graph capture's, say) do not allocate."""
        if isinstance(num_points, bool):
            raise KdslTypeError(f"HashGrid.reserve num_points must be an int, not {num_points!r}")
        try:
            n = operator.index(num_points)
        except TypeError:
            raise KdslTypeError(
                f"HashGrid.reserve num_points must be an int, not {num_points!r}"
            ) from None
        if not 0 <= n <= MAX_CELLS:
            raise HashGridError(f"HashGrid.reserve num_points must be in [0, 2**31 - 1], not {n}")
        if n > self._builder.capacity:
            self._builder.reserve(n)
            inv, self._recorded = self._recorded[1], None  # new buffers: a new record
            self._write_record(inv)

    def build(self, points: array, radius: float) -> None:
        """Bucket ``points`` (a 1-d ``vec3`` array on the grid's device) into cells of
        width ``radius`` (> 0; query with about the same radius for 27-cell queries)."""
        # A rebuild of the last build's array with its radius skips the checks they
        # passed then (host time: a GPU rebuild is a few launches).
        key = (type(radius), radius)
        if key != self._radius_key:
            self._inv = _cell_width_inv(radius)
            self._radius_key = key
        inv = self._inv
        steps = self._builder.steps
        if steps is None or points is not steps.points:
            self._check_points(points)
        n = points.shape[0]
        if n > self._builder.capacity:
            self.reserve(n)
        if n or self.num_points:
            try:
                self._builder.run(points, n, inv)
            except BaseException:  # the builder has emptied the tables: an empty grid
                self.num_points = 0
                self._write_record(inv)
                raise
        self.num_points = n
        self.radius = float(radius)
        self._write_record(inv)

    def _check_points(self, points: Any) -> None:
        if not isinstance(points, array) or type_of(points.dtype) != VEC3 or points.ndim != 1:
            raise KdslTypeError(
                f"HashGrid.build points must be a 1-d kdsl.array of vec3, not {points!r}"
            )
        if points.device != self.device:
            raise KdslTypeError(
                f"HashGrid.build points are on {points.device}, the grid on {self.device}"
            )

    def _write_record(self, inv: np.float32) -> None:
        n = self.num_points
        state = (n, inv)
        if state == self._recorded:
            return  # the same buffers (``reserve`` forgets this), count and cell width
        b = self._builder
        self._record.write(
            {
                "point_ids": b.point_ids[:n], "cell_starts": b.cell_starts,
                "cell_ends": b.cell_ends, "dim_x": self.dim_x, "dim_y": self.dim_y,
                "dim_z": self.dim_z, "num_points": n, "cell_width_inv": inv,
            }
        )  # fmt: skip
        self._recorded = state
