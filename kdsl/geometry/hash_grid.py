"""``kdsl.HashGrid``: points bucketed into a wrapped grid of cells, queried from kernels.

The build runs on the grid's device as kdsl kernels, with no read back to the host:
each point's bucket (``kdsl.stdlib.hash_grid.hash_grid_cell``), a stable radix sort of
(bucket, point index) pairs, then each bucket's range of the sorted order, found by
comparing sorted neighbours. The buffers are kept between builds and grow only when
the point count exceeds what they hold (``reserve``). The queries are kernel code in
``kdsl.stdlib.hash_grid``.
"""

from __future__ import annotations

import math
import operator
from typing import Any

import numpy as np

from kdsl.errors import KdslError, KdslTypeError
from kdsl.frontend.api import kernel, tid
from kdsl.ir import types as T
from kdsl.runtime.alloc import empty, zeros
from kdsl.runtime.array import array
from kdsl.runtime.device import get_device
from kdsl.runtime.launch import launch
from kdsl.runtime.objects import ObjectRecord
from kdsl.stdlib.hash_grid import HashGridRecord, hash_grid_cell, hash_grid_cell_coord
from kdsl.types import float32, int32, type_of, vec3
from kdsl.utils import radix_sort_pairs

VEC3 = T.VectorType(3, T.F32)
#: The most buckets a grid may have: bucket indices are int32 (Warp's limit too).
MAX_CELLS = 2**31 - 1


class HashGridError(KdslError, ValueError, RuntimeError):
    """A bad ``HashGrid`` argument value (a ``ValueError`` and a ``RuntimeError`` too, the
    classes Warp raises for these)."""


@kernel
def _bucket_points(
    points: array(dtype=vec3), inv: float32, dim_x: int32, dim_y: int32, dim_z: int32,
    keys: array(dtype=int32), values: array(dtype=int32),
):  # fmt: skip
    i = tid()
    p = points[i]
    x = hash_grid_cell_coord(p[0] * inv)
    y = hash_grid_cell_coord(p[1] * inv)
    z = hash_grid_cell_coord(p[2] * inv)
    keys[i] = hash_grid_cell(x, y, z, dim_x, dim_y, dim_z)
    values[i] = i


@kernel
def _bucket_ranges(
    keys: array(dtype=int32), n: int32, starts: array(dtype=int32), ends: array(dtype=int32)
):  # fmt: skip
    # Sorted keys: a bucket starts where its key differs from the previous one and ends
    # where it differs from the next; each bucket's two entries are written once.
    i = tid()
    c = keys[i]
    if i == 0 or keys[i - 1] != c:
        starts[c] = i
    if i == n - 1 or keys[i + 1] != c:
        ends[c] = i + 1


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
        self._cell_starts = zeros(cells, dtype=int32, device=self.device)
        self._cell_ends = zeros(cells, dtype=int32, device=self.device)
        self._capacity = -1
        self._keys = self._values = empty(0, dtype=int32, device=self.device)
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
        return self._capacity >= 0

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
        if n > self._capacity:
            # The sort needs twice the count (its second half is scratch space).
            self._keys = empty(2 * n, dtype=int32, device=self.device)
            self._values = empty(2 * n, dtype=int32, device=self.device)
            self._capacity = n

    def build(self, points: array, radius: float) -> None:
        """Bucket ``points`` (a 1-d ``vec3`` array on the grid's device) into cells of
        width ``radius`` (> 0; query with about the same radius for 27-cell queries)."""
        inv = _cell_width_inv(radius)
        if not isinstance(points, array) or type_of(points.dtype) != VEC3 or points.ndim != 1:
            raise KdslTypeError(
                f"HashGrid.build points must be a 1-d kdsl.array of vec3, not {points!r}"
            )
        if points.device != self.device:
            raise KdslTypeError(
                f"HashGrid.build points are on {points.device}, the grid on {self.device}"
            )
        n = points.shape[0]
        self.reserve(n)
        self._cell_starts.zero_()
        self._cell_ends.zero_()
        if n:
            keys, values = self._keys, self._values
            launch(_bucket_points, dim=n, device=self.device,
                   inputs=[points, inv, self.dim_x, self.dim_y, self.dim_z, keys, values])  # fmt: skip
            radix_sort_pairs(keys, values, n, 0, max(1, (self.num_cells - 1).bit_length()))
            launch(_bucket_ranges, dim=n, device=self.device,
                   inputs=[keys, n, self._cell_starts, self._cell_ends])  # fmt: skip
        self.num_points = n
        self.radius = float(radius)
        self._write_record(inv)

    def _write_record(self, inv: np.float32) -> None:
        n = self.num_points
        state = (n, float(inv), self._values.ptr)
        if state == self._recorded:
            return  # the same buffers, count and cell width: the record is current
        self._record.write(
            {
                "point_ids": self._values[:n], "cell_starts": self._cell_starts,
                "cell_ends": self._cell_ends, "dim_x": self.dim_x, "dim_y": self.dim_y,
                "dim_z": self.dim_z, "num_points": n, "cell_width_inv": inv,
            }
        )  # fmt: skip
        self._recorded = state
