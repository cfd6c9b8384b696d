"""``kdsl.HashGrid``: points bucketed into a wrapped grid of cells, queried from kernels.

The build runs on the grid's device with no read back to the host, as two kdsl kernels
around one sort:

1. ``_bucket_keys``: each point's key, its bucket (``kdsl.stdlib.hash_grid.hash_grid_cell``)
   in the high 32 bits and its index in the low 32 (unique keys, so any sort is stable),
   and, first, the bucket of the previous build's ``i``-th key emptied in the cell tables
   (those buckets are the tables' only nonzero entries);
2. a sort of the keys in place (``kdsl.utils.sort.SortKeys``: CUB's radix sort on a
   GPU, NumPy's sort on the CPU);
3. ``_bucket_ranges``: the point order (the keys' low halves) and each bucket's range of
   it, found by comparing sorted neighbours.

The build's work is thus in the point count, never in the cell count (a 128^3 grid has
2M cells, ten times a 200k-point build's points): the tables are zeroed once, when
allocated, and then only the previous build's buckets are emptied. The buffers are kept
between builds and grow only when the point count exceeds what they hold (``reserve``);
the launches are prepared once per point array and count. The queries are kernel code
in ``kdsl.stdlib.hash_grid``.
"""

from __future__ import annotations

import math
import operator
from collections.abc import Callable
from typing import Any

import numpy as np

from kdsl.errors import KdslError, KdslTypeError
from kdsl.frontend.api import kernel, tid
from kdsl.ir import types as T
from kdsl.runtime.alloc import copy, empty, zeros
from kdsl.runtime.array import array
from kdsl.runtime.device import get_device
from kdsl.runtime.launch import Launch, launch
from kdsl.runtime.objects import ObjectRecord
from kdsl.stdlib.hash_grid import HashGridRecord, hash_grid_cell, hash_grid_cell_coord
from kdsl.types import float32, int32, type_of, uint64, vec3
from kdsl.utils.sort import SortKeys

VEC3 = T.VectorType(3, T.F32)
#: The most buckets a grid may have: bucket indices are int32 (Warp's limit too).
MAX_CELLS = 2**31 - 1


class HashGridError(KdslError, ValueError, RuntimeError):
    """A bad ``HashGrid`` argument value (a ``ValueError`` and a ``RuntimeError`` too, the
    classes Warp raises for these)."""


@kernel
def _bucket_keys(
    points: array(dtype=vec3), n: int32, emptied: int32, inv: float32, dim_x: int32,
    dim_y: int32, dim_z: int32, keys: array(dtype=uint64), starts: array(dtype=int32),
    ends: array(dtype=int32),
):  # fmt: skip
    # Launched over max(n, emptied): keys[:emptied] hold the previous build's sorted
    # keys, whose buckets are emptied before this thread's key replaces its slot.
    i = tid()
    if i < emptied:
        old = int32(keys[i] >> uint64(32))
        starts[old] = 0
        ends[old] = 0
    if i < n:
        p = points[i]
        x = hash_grid_cell_coord(p[0] * inv)
        y = hash_grid_cell_coord(p[1] * inv)
        z = hash_grid_cell_coord(p[2] * inv)
        c = hash_grid_cell(x, y, z, dim_x, dim_y, dim_z)
        keys[i] = (uint64(c) << uint64(32)) | uint64(i)


@kernel
def _bucket_ranges(
    keys: array(dtype=uint64), n: int32, point_ids: array(dtype=int32),
    starts: array(dtype=int32), ends: array(dtype=int32),
):  # fmt: skip
    # Sorted keys: a bucket starts where its bucket differs from the previous key's and
    # ends where it differs from the next one's; each bucket's two entries are written once.
    i = tid()
    k = keys[i]
    c = int32(k >> uint64(32))
    point_ids[i] = int32(k & uint64(0xFFFFFFFF))
    if i == 0 or int32(keys[i - 1] >> uint64(32)) != c:
        starts[c] = i
    if i == n - 1 or int32(keys[i + 1] >> uint64(32)) != c:
        ends[c] = i + 1


class _Build:
    """One build's prepared steps for ``points`` (``n`` of them) after a build of
    ``emptied`` points over the same buffers: run again while those stay the same (it
    holds ``points``, as its prepared launch does, until the grid builds another array)."""

    __slots__ = ("emptied", "inv", "keys_step", "n", "points", "steps")

    def __init__(self, grid: HashGrid, points: array, n: int, emptied: int, inv: np.float32):
        self.points, self.n, self.emptied, self.inv = points, n, emptied, inv
        device, keys = grid.device, grid._keys
        tables = [grid._cell_starts, grid._cell_ends]
        self.keys_step: Launch = launch(
            _bucket_keys, dim=max(n, emptied), device=device, record_cmd=True,
            inputs=[points, n, emptied, inv, grid.dim_x, grid.dim_y, grid.dim_z, keys, *tables],
        )  # fmt: skip
        self.steps: list[Callable[[], None]] = [self.keys_step.launch]
        if n:
            ranges = launch(_bucket_ranges, dim=n, device=device, record_cmd=True,
                            inputs=[keys, n, grid._point_ids, *tables])  # fmt: skip
            self.steps += [SortKeys(keys[:n]), ranges.launch]

    def matches(self, points: array, n: int, emptied: int) -> bool:
        """Whether this build's steps fit a build of ``points`` after ``emptied``."""
        return points is self.points and n == self.n and emptied == self.emptied

    def run(self, inv: np.float32) -> None:
        """Run the steps with cell width ``1 / inv``."""
        if inv != self.inv:
            self.keys_step.set_param_at_index(3, inv)
            self.inv = inv
        for step in self.steps:
            step()


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
        # Every build leaves the tables zero but for its own buckets' entries.
        self._cell_starts = zeros(cells, dtype=int32, device=self.device)
        self._cell_ends = zeros(cells, dtype=int32, device=self.device)
        self._capacity = -1
        self._keys = empty(0, dtype=uint64, device=self.device)
        self._point_ids = empty(0, dtype=int32, device=self.device)
        self._build: _Build | None = None
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
            keys = empty(n, dtype=uint64, device=self.device)
            point_ids = empty(n, dtype=int32, device=self.device)
            if self.num_points:  # the built grid stays as it is, in the new buffers
                copy(keys, self._keys, count=self.num_points)
                copy(point_ids, self._point_ids, count=self.num_points)
            self._keys, self._point_ids, self._capacity = keys, point_ids, n
            self._build = None
            inv, self._recorded = self._recorded[1], None
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
        step = self._build
        if step is None or points is not step.points:
            self._check_points(points)
        n = points.shape[0]
        if n > self._capacity:
            self.reserve(n)
            step = self._build
        emptied = self.num_points
        if n or emptied:
            if step is None or not step.matches(points, n, emptied):
                step = self._build = _Build(self, points, n, emptied, inv)
            step.run(inv)
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
        self._record.write(
            {
                "point_ids": self._point_ids[:n], "cell_starts": self._cell_starts,
                "cell_ends": self._cell_ends, "dim_x": self.dim_x, "dim_y": self.dim_y,
                "dim_z": self.dim_z, "num_points": n, "cell_width_inv": inv,
            }
        )  # fmt: skip
        self._recorded = state
