"""Sparse marching cubes of an implicit function, as Warp 1.19's ``warp.geometry``:
``lipschitz_octree``, ``sparse_marching_cubes_from_cells`` and ``sparse_marching_cubes``.

A Lipschitz octree (libigl's ``lipschitz_octree``) keeps, level by level, the cells
whose centre value is within ``lipschitz_bound`` times half the cell's diagonal of the
threshold: only those can hold the surface. Marching cubes then runs on the leaves
alone. Every step is kdsl kernels on the device, with ``kdsl.utils.array_scan`` for
compaction and ``radix_sort_pairs`` to number the leaves' shared corners; the host
reads back only counts (one per octree level, the unique corners, vertices and
triangles), as Warp does.

The output is Warp's: corners are numbered in the order of their packed subscript
``(i * s + j) * s + k``, a vertex per crossing edge in the order of its lower corner
then its axis, triangles cell by cell (octree order, or the caller's) from Bourke's
table. With the same grid, ``sparse_marching_cubes`` gives the surface
``IsoSurfaceMarchingCubes.extract`` gives on the sampled field, in another order.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from typing import Any

import numpy as np

from kdsl.frontend.api import abs as kabs
from kdsl.frontend.api import atomic_max, atomic_min, cw_mul, kernel, lerp, tid
from kdsl.frontend.kernel import Function
from kdsl.geometry.iso_surface import Bounds, as_bound, check_node_counts, resolve_domain_bounds
from kdsl.geometry.marching_cubes import (
    MarchingCubesError,
    MarchingCubesTypeError,
    case_tables,
    check_threshold,
    edge_fraction,
)
from kdsl.geometry.marching_cubes_tables import (
    CUBE_CORNER_OFFSETS,
    TRI_LOCAL_INDICES,
    edge_node_and_axis,
)
from kdsl.ir import types as T
from kdsl.runtime.alloc import empty, full, zeros
from kdsl.runtime.array import array
from kdsl.runtime.device import Device, get_device
from kdsl.runtime.launch import launch
from kdsl.types import float32, int32, int64, type_of, vec3, vec3i
from kdsl.utils import array_scan, radix_sort_pairs

#: An implicit function: a kdsl array of vec3 points in, one float32 value per point out.
Field = Callable[[array], array]

_BACKEND: ContextVar[str | None] = ContextVar("sparse_marching_cubes_backend", default=None)


@contextmanager
def kernels_on(backend: str) -> Iterator[None]:
    """Run this module's kernels on ``backend`` (the ``"interp"`` reference, in tests)
    instead of the device's default backend, inside the ``with`` block."""
    token = _BACKEND.set(backend)
    try:
        yield
    finally:
        _BACKEND.reset(token)


def _launch(kernel: Any, **kwargs: Any) -> None:
    launch(kernel, backend=_BACKEND.get(), **kwargs)


@kernel
def _cell_centres(cells: array(dtype=vec3i), origin: vec3, width: vec3, out: array(dtype=vec3)):
    i = tid()
    c = cells[i]
    out[i] = origin + cw_mul(width, vec3(float32(c[0]) + 0.5, float32(c[1]) + 0.5,
                                         float32(c[2]) + 0.5))  # fmt: skip


@kernel
def _near_surface(values: array(dtype=float32), threshold: float32, band: float32,
                  keep: array(dtype=int32)):  # fmt: skip
    i = tid()
    keep[i] = 0
    if kabs(values[i] - threshold) <= band:  # a NaN value is never near
        keep[i] = 1


@kernel
def _inside_grid(cells: array(dtype=vec3i), ncells: vec3i, keep: array(dtype=int32)):
    i = tid()
    c = cells[i]
    keep[i] = 0
    if c[0] < ncells[0] and c[1] < ncells[1] and c[2] < ncells[2]:
        keep[i] = 1


@kernel
def _compact(cells: array(dtype=vec3i), keep: array(dtype=int32), scan: array(dtype=int32),
             out: array(dtype=vec3i)):  # fmt: skip
    i = tid()
    if keep[i] == 1:
        out[scan[i] - 1] = cells[i]


@kernel
def _subdivide(cells: array(dtype=vec3i), out: array(dtype=vec3i)):
    i = tid()
    c = cells[i] * 2
    for child in range(8):  # x fastest, then y, then z
        out[8 * i + child] = c + vec3i(child & 1, (child >> 1) & 1, (child >> 2) & 1)


@kernel
def _bounds(cells: array(dtype=vec3i), lo: array(dtype=int32), hi: array(dtype=int32)):
    c = cells[tid()]
    for a in range(3):
        atomic_min(lo, a, c[a])
        atomic_max(hi, a, c[a])


@kernel
def _corner_codes(cells: array(dtype=vec3i), corners: array(dtype=vec3i), offset: vec3i,
                  stride: int64, codes: array(dtype=int64), order: array(dtype=int32)):  # fmt: skip
    i = tid()
    for c in range(8):
        s = cells[i] + corners[c] - offset
        codes[i * 8 + c] = (int64(s[0]) * stride + int64(s[1])) * stride + int64(s[2])
        order[i * 8 + c] = i * 8 + c


@kernel
def _number_unique(codes: array(dtype=int64), first: array(dtype=int32)):
    i = tid()
    first[i] = 1
    if i > 0 and codes[i] == codes[i - 1]:
        first[i] = 0


@kernel
def _scatter_unique(
    codes: array(dtype=int64), order: array(dtype=int32), first: array(dtype=int32),
    rank: array(dtype=int32), cell_corners: array(dtype=int32), unique_codes: array(dtype=int64),
    source: array(dtype=int32),
):  # fmt: skip
    i = tid()
    u = rank[i] - 1
    cell_corners[order[i]] = u
    if first[i] == 1:
        unique_codes[u] = codes[i]
        source[u] = order[i]


@kernel
def _corner_positions(codes: array(dtype=int64), stride: int64, base: vec3, width: vec3,
                      out: array(dtype=vec3)):  # fmt: skip
    # Subscripts relative to the lowest corner, so float32 holds them exactly.
    i = tid()
    code = codes[i]
    k = code % stride
    j = (code // stride) % stride
    x = code // (stride * stride)
    out[i] = base + cw_mul(width, vec3(float32(int32(x)), float32(int32(j)), float32(int32(k))))


@kernel
def _gather(source: array(dtype=int32), values: array(dtype=float32), out: array(dtype=float32)):
    i = tid()
    out[i] = values[source[i]]


@kernel
def _mark_edges(
    cell_corners: array(dtype=int32, ndim=2), values: array(dtype=float32), threshold: float32,
    case_ranges: array(dtype=int32), edges: array(dtype=int32),
    active: array(dtype=int32), upper: array(dtype=int32), tris: array(dtype=int32),
):  # fmt: skip
    cell = tid()
    code = 0
    for c in range(8):
        if values[cell_corners[cell, c]] >= threshold:  # a NaN is below every threshold
            code = code | (1 << c)
    first = case_ranges[code]
    last = case_ranges[code + 1]
    tris[cell] = (last - first) // 3
    for e in range(first, last):
        # A packed table edge: its lower corner (bits 0-2), upper corner (3-5), axis (6-7).
        p = edges[e]
        slot = cell_corners[cell, p & 7] * 3 + (p >> 6)
        # Every cell around an edge writes the same values: the race is benign.
        active[slot] = 1
        upper[slot] = cell_corners[cell, (p >> 3) & 7]


@kernel
def _emit_vertices(
    active: array(dtype=int32), index: array(dtype=int32), upper: array(dtype=int32),
    positions: array(dtype=vec3), values: array(dtype=float32), threshold: float32,
    verts: array(dtype=vec3),
):  # fmt: skip
    slot = tid()
    if active[slot] == 1:
        lo = slot // 3
        hi = upper[slot]
        a = values[lo]
        t = edge_fraction(a, values[hi], threshold)
        verts[index[slot] - 1] = lerp(positions[lo], positions[hi], t)


@kernel
def _emit_faces(
    cell_corners: array(dtype=int32, ndim=2), values: array(dtype=float32), threshold: float32,
    case_ranges: array(dtype=int32), edges: array(dtype=int32), index: array(dtype=int32),
    tri_end: array(dtype=int32), indices: array(dtype=int32),
):  # fmt: skip
    cell = tid()
    code = 0
    for c in range(8):
        if values[cell_corners[cell, c]] >= threshold:
            code = code | (1 << c)
    first = case_ranges[code]
    last = case_ranges[code + 1]
    out = 3 * tri_end[cell] - (last - first)
    for e in range(first, last):
        p = edges[e]
        indices[out + e - first] = index[cell_corners[cell, p & 7] * 3 + (p >> 6)] - 1


def _packed_table_edges() -> np.ndarray:
    """Each table edge as lower corner | upper corner << 3 | axis << 6."""
    packed = []
    for e in range(12):
        dx, dy, dz, axis = edge_node_and_axis(e)
        lower = CUBE_CORNER_OFFSETS.index((dx, dy, dz))
        step = [0, 0, 0]
        step[axis] = 1
        upper = CUBE_CORNER_OFFSETS.index((dx + step[0], dy + step[1], dz + step[2]))
        packed.append(lower | upper << 3 | axis << 6)
    return np.array([packed[e] for e in TRI_LOCAL_INDICES], dtype=np.int32)


_EDGES: dict[str, tuple[array, array]] = {}


def _tables(device: Device) -> tuple[array, array, array]:
    """``(case_ranges, packed table edges, corner offsets)`` on ``device``."""
    if device.alias not in _EDGES:
        _EDGES[device.alias] = (
            array(_packed_table_edges(), dtype=int32, device=device),
            array(np.array(CUBE_CORNER_OFFSETS, np.int32), dtype=vec3i, device=device),
        )
    return (case_tables(device)[0], *_EDGES[device.alias])


def _scan_total(keep: array, scan: array) -> int:
    """Inclusive scan of ``keep`` into ``scan``; the total, read back."""
    array_scan(keep, scan, inclusive=True)
    return int(scan[scan.shape[0] - 1 :].numpy()[0])


def _keep(cells: array, keep: array) -> array:
    """The cells whose ``keep`` is 1, in order."""
    scan = empty(cells.shape[0], dtype=int32, device=cells.device)
    n = _scan_total(keep, scan)
    out = empty(n, dtype=vec3i, device=cells.device)
    if n:
        _launch(_compact, dim=cells.shape[0], inputs=[cells, keep, scan, out], device=cells.device)
    return out


def _evaluator(field: Any) -> Field:
    if isinstance(field, Function):
        raise MarchingCubesTypeError(
            "field must be a batched callable, evaluate(points: array of vec3) -> array of "
            "float32, not a single-point @kdsl.func: launch the function over the points in "
            "a kernel of your own and return its output array"
        )
    if not callable(field):
        raise MarchingCubesTypeError(f"field must be a callable, not {type(field).__name__}")

    def evaluate(points: array) -> array:
        values = field(points)
        if not isinstance(values, array) or type_of(values.dtype) != T.F32:
            raise MarchingCubesTypeError(f"the implicit function must return a kdsl.array of "
                                         f"float32, not {values!r:.80}")  # fmt: skip
        if values.shape[0] != points.shape[0] or values.ndim != 1:
            raise MarchingCubesError(f"the implicit function returned shape {values.shape} "
                                     f"for {points.shape[0]} points")  # fmt: skip
        if values.device != points.device:
            raise MarchingCubesTypeError(f"the implicit function returned values on "
                                         f"{values.device} for points on {points.device}")  # fmt: skip
        return values

    return evaluate


def _octree(evaluate: Field, origin: np.ndarray, root: np.ndarray, depth: int,
            threshold: np.float32, lipschitz: float, device: Device) -> array:  # fmt: skip
    cells = array(np.zeros((1, 3), np.int32), dtype=vec3i, device=device)
    for level in range(depth + 1):
        width = root * np.float32(1.0 / (1 << level))
        band = np.float32(lipschitz * 0.5 * float(np.linalg.norm(width)))
        n = cells.shape[0]
        centres = empty(n, dtype=vec3, device=device)
        _launch(_cell_centres, dim=n, inputs=[cells, vec3(*origin), vec3(*width), centres],
               device=device, record_tape=False)  # fmt: skip
        keep = empty(n, dtype=int32, device=device)
        _launch(_near_surface, dim=n, inputs=[evaluate(centres), threshold, band, keep],
               device=device, record_tape=False)  # fmt: skip
        cells = _keep(cells, keep)
        if cells.shape[0] == 0 or level == depth:
            return cells
        children = empty(8 * cells.shape[0], dtype=vec3i, device=device)
        _launch(_subdivide, dim=cells.shape[0], inputs=[cells, children], device=device,
               record_tape=False)  # fmt: skip
        cells = children
    return cells


class _Corners:
    """A set of cells' shared corners: ``cell_corners[cell, c]`` numbers corner ``c`` of
    ``cell`` among the unique corners (sorted by packed subscript), at ``positions``;
    ``source[u]`` is one flat ``cell * 8 + c`` slot of unique corner ``u``."""

    def __init__(self, cells: array, offset: np.ndarray, stride: int, base: np.ndarray,
                 width: np.ndarray) -> None:  # fmt: skip
        device, n = cells.device, cells.shape[0]
        m = 8 * n
        _, _, corners = _tables(device)
        keys = empty(2 * m, dtype=int64, device=device)  # the sort's second half: scratch
        order = empty(2 * m, dtype=int32, device=device)
        _launch(_corner_codes, dim=n, device=device,
               inputs=[cells, corners, vec3i(*offset), stride, keys, order])  # fmt: skip
        # Stable: among equal codes the lowest cell * 8 + corner slot comes first.
        radix_sort_pairs(keys, order, m, 0, max(1, (stride**3 - 1).bit_length()))
        first = empty(m, dtype=int32, device=device)
        _launch(_number_unique, dim=m, inputs=[keys, first], device=device)
        rank = empty(m, dtype=int32, device=device)
        self.count = _scan_total(first, rank)
        self.cell_corners = empty((n, 8), dtype=int32, device=device)
        codes = empty(self.count, dtype=int64, device=device)
        self.source = empty(self.count, dtype=int32, device=device)
        _launch(_scatter_unique, dim=m, device=device,
               inputs=[keys, order, first, rank, self.cell_corners.flatten(), codes,
                       self.source])  # fmt: skip
        self.positions = empty(self.count, dtype=vec3, device=device)
        _launch(_corner_positions, dim=self.count, device=device,
               inputs=[codes, stride, vec3(*base), vec3(*width), self.positions])  # fmt: skip


def _extract(corners: _Corners, values: array, threshold: np.float32) -> tuple[array, array]:
    """Marching cubes over the cells of ``corners`` with unique-corner ``values``."""
    device = values.device
    n = corners.cell_corners.shape[0]
    ranges, edges, _ = _tables(device)
    slots = 3 * corners.count
    active = zeros(slots, dtype=int32, device=device)
    upper = empty(slots, dtype=int32, device=device)
    tris = empty(n, dtype=int32, device=device)
    _launch(_mark_edges, dim=n, device=device,
           inputs=[corners.cell_corners, values, threshold, ranges, edges, active, upper, tris])  # fmt: skip
    index = empty(slots, dtype=int32, device=device)
    num_verts = _scan_total(active, index)
    num_tris = _scan_total(tris, tris)
    verts = empty(num_verts, dtype=vec3, device=device, requires_grad=values.requires_grad)
    indices = empty(3 * num_tris, dtype=int32, device=device)
    if num_verts:
        _launch(_emit_vertices, dim=slots, device=device,
               inputs=[active, index, upper, corners.positions, values, threshold, verts])  # fmt: skip
        _launch(_emit_faces, dim=n, device=device,
               inputs=[corners.cell_corners, values, threshold, ranges, edges, index, tris,
                       indices])  # fmt: skip
    return verts, indices


def _empty(device: Device) -> tuple[array, array]:
    return empty(0, dtype=vec3, device=device), empty(0, dtype=int32, device=device)


def _check_positive(name: str, value: Any, allow_zero: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.number):
        raise MarchingCubesTypeError(f"{name} must be a number, not {value!r}")
    v = float(value)
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        raise MarchingCubesError(f"{name} must be {'>= 0' if allow_zero else '> 0'} and finite, "
                                 f"not {value!r}")  # fmt: skip
    return v


def lipschitz_octree(
    field: Field, origin: Bounds, root_width: float, max_depth: int, threshold: float = 0.0,
    lipschitz_bound: float = 1.0, device: Any = None,
) -> tuple[array, float]:  # fmt: skip
    """``(cells, cell_width)``: the leaves at ``max_depth`` of the octree over the cube
    ``[origin, origin + root_width]`` that may hold the ``threshold`` level set of a
    ``field`` whose Lipschitz constant is at most ``lipschitz_bound`` (Warp 1.19's
    ``warp.geometry.lipschitz_octree``). ``cells`` are vec3i minimum-corner subscripts:
    cell ``(i, j, k)`` spans ``origin + cell_width * [(i, j, k), (i + 1, j + 1, k + 1)]``;
    ``field`` maps a vec3 array of points to a float32 array of values."""
    if isinstance(max_depth, bool) or not isinstance(max_depth, int | np.integer):
        raise MarchingCubesTypeError(f"max_depth must be an int, not {max_depth!r}")
    if not 0 <= max_depth <= 20:  # 2**21 cells per axis: corner codes still fit int64
        raise MarchingCubesError(f"max_depth must be in [0, 20], not {max_depth}")
    width = _check_positive("root_width", root_width)
    lipschitz = _check_positive("lipschitz_bound", lipschitz_bound, allow_zero=True)
    device = get_device(device)
    lo = as_bound("origin", origin)
    root = np.full(3, width, np.float32)
    cells = _octree(_evaluator(field), lo, root, int(max_depth), check_threshold(threshold),
                    lipschitz, device)  # fmt: skip
    return cells, width / float(1 << int(max_depth))


def _cell_array(cells: Any, device: Device) -> array:
    if isinstance(cells, array):
        if cells.device != device:
            raise MarchingCubesTypeError(f"cells are on {cells.device}, not {device}")
        t = type_of(cells.dtype)
        if t == type_of(vec3i) and cells.ndim == 1:
            return cells.contiguous()
        if t == T.I32 and cells.ndim == 2 and cells.shape[1] == 3:
            return cells.contiguous().reshape((-1, 3)).view(vec3i)
        raise MarchingCubesTypeError(f"cells must be vec3i or (N, 3) int32, not {cells!r:.80}")
    c = np.asarray(cells)
    if c.dtype.kind not in "iu" or c.size % 3:
        raise MarchingCubesTypeError("cells must be integer subscripts, three per cell")
    c64 = c.reshape(-1, 3).astype(np.int64)
    if c64.size and (c64.min() < -(2**31) or c64.max() >= 2**31 - 1):
        raise MarchingCubesError("cell subscripts must fit int32 (with their + 1 corner)")
    return array(c64.astype(np.int32), dtype=vec3i, device=device)


def _value_array(values: Any, n: int, device: Device) -> array:
    if isinstance(values, array):
        if values.device != device:
            raise MarchingCubesTypeError(f"corner_values are on {values.device}, not {device}")
        if type_of(values.dtype) != T.F32:
            raise MarchingCubesTypeError(
                f"corner_values must be float32, not {type_of(values.dtype)}"
            )
        v = values.contiguous()
    else:
        v = array(np.ascontiguousarray(values, dtype=np.float32), dtype=float32, device=device)
    if v.size != 8 * n:
        raise MarchingCubesError(f"corner_values must hold 8 values per cell ({8 * n}), "
                                 f"not {v.size}")  # fmt: skip
    return v.reshape((8 * n,))


def sparse_marching_cubes_from_cells(
    cells: Any, corner_values: Any, origin: Bounds = (0.0, 0.0, 0.0), cell_width: float = 1.0,
    threshold: float = 0.0, device: Any = None,
) -> tuple[array, array]:  # fmt: skip
    """``(verts, indices)`` of the ``threshold`` iso-surface over the given cells
    (Warp 1.19's ``warp.geometry.sparse_marching_cubes_from_cells``): ``cells`` are
    unique ``(i, j, k)`` minimum-corner subscripts (vec3i, ``(N, 3)`` int32 or array-like),
    ``corner_values`` 8 values per cell in ``CUBE_CORNER_OFFSETS`` order (a corner shared
    by cells should have one value; one of its entries is used). Vertices shared
    between cells are welded, so a closed surface is watertight. Gradients flow from
    ``verts`` to ``corner_values`` under ``kdsl.Tape``."""
    device = get_device(device)
    width = _check_positive("cell_width", cell_width)
    thr = check_threshold(threshold)
    origin64 = as_bound("origin", origin).astype(np.float64)
    cells = _cell_array(cells, device)
    n = cells.shape[0]
    values = _value_array(corner_values, n, device)
    if n == 0:
        return _empty(device)
    lo = full(3, 2**31 - 1, dtype=int32, device=device)
    hi = full(3, -(2**31), dtype=int32, device=device)
    _launch(_bounds, dim=n, inputs=[cells, lo, hi], device=device)
    low, high = lo.numpy().astype(np.int64), hi.numpy().astype(np.int64)
    stride = int((high - low).max()) + 2
    if stride**3 >= 2**63:
        raise MarchingCubesError(f"cell subscripts span {stride} corners per axis: too many "
                                 f"for 64-bit corner codes")  # fmt: skip
    # The lowest corner's position in float64, so subscripts stay small in float32.
    width32 = np.float32(width)
    base = (origin64 + float(width32) * low).astype(np.float32)
    corners = _Corners(cells, low, stride, base, np.full(3, width32, np.float32))
    unique = empty(corners.count, dtype=float32, device=device,
                   requires_grad=values.requires_grad)  # fmt: skip
    _launch(_gather, dim=corners.count, inputs=[corners.source, values, unique], device=device)
    return _extract(corners, unique, thr)


def sparse_marching_cubes(
    field: Field, nx: int, ny: int, nz: int, *, lower: Bounds = None, upper: Bounds = None,
    threshold: float = 0.0, lipschitz_bound: float = 1.0, device: Any = None,
    return_stats: bool = False,
) -> tuple[array, array] | tuple[array, array, dict]:  # fmt: skip
    """``(verts, indices)`` of the ``threshold`` iso-surface of the implicit ``field`` on
    the grid of ``nx * ny * nz`` nodes over ``[lower, upper]`` (Warp 1.19's
    ``warp.geometry.sparse_marching_cubes``): the surface ``IsoSurfaceMarchingCubes``
    extracts from the field sampled on that grid, found through a Lipschitz octree so
    that only cells near the surface are evaluated. ``field`` maps a vec3 array of
    points to a float32 array of values, with Lipschitz constant at most
    ``lipschitz_bound`` (1 for a signed distance). ``return_stats`` adds a dict:
    ``leaf_cells``, ``unique_corners``, ``field_evaluations``, ``resolution``,
    ``requested_ncells``, ``culled_cells``."""
    nx, ny, nz = check_node_counts(nx, ny, nz)
    lipschitz = _check_positive("lipschitz_bound", lipschitz_bound, allow_zero=True)
    thr = check_threshold(threshold)
    device = get_device(device)
    lo, delta = resolve_domain_bounds((nx, ny, nz), lower, upper)
    ncells = (nx - 1, ny - 1, nz - 1)
    depth = (max(ncells) - 1).bit_length()
    resolution = 1 << depth
    evaluate = _evaluator(field)
    stats: dict[str, Any] = {"leaf_cells": 0, "unique_corners": 0, "field_evaluations": 0,
                             "resolution": resolution, "requested_ncells": ncells,
                             "culled_cells": 0}  # fmt: skip

    def counted(points: array) -> array:
        stats["field_evaluations"] += points.shape[0]
        return evaluate(points)

    def finish(verts: array, indices: array):
        return (verts, indices, stats) if return_stats else (verts, indices)

    cells = _octree(counted, lo, delta * np.float32(resolution), depth, thr, lipschitz, device)
    if cells.shape[0] and ncells != (resolution,) * 3:
        # The root box is padded to a power of two per axis: drop the padding's cells.
        keep = empty(cells.shape[0], dtype=int32, device=device)
        _launch(_inside_grid, dim=cells.shape[0], inputs=[cells, vec3i(*ncells), keep],
               device=device, record_tape=False)  # fmt: skip
        kept = _keep(cells, keep)
        stats["culled_cells"] = cells.shape[0] - kept.shape[0]
        cells = kept
    if cells.shape[0] == 0:
        return finish(*_empty(device))
    stats["leaf_cells"] = cells.shape[0]
    corners = _Corners(cells, np.zeros(3, np.int64), resolution + 1, lo, delta)
    stats["unique_corners"] = corners.count
    return finish(*_extract(corners, counted(corners.positions), thr))


__all__ = ["lipschitz_octree", "sparse_marching_cubes", "sparse_marching_cubes_from_cells"]
