"""Marching cubes on a dense float32 field, as kdsl kernels on the field's device.

``extract_surface`` gives Warp's output: one vertex per grid edge the surface crosses
(shared by every triangle that uses it), vertices ordered by the edge's lower node (x
slowest, z fastest) then its axis, and each cell's triangles from Bourke's table in
cell order. Three steps, with one read back to the host:

1. ``_classify_nodes``, one thread per node: the node's cell case code (its 8 corners
   against the threshold) and which of its 3 edges towards +x, +y, +z cross the
   surface, kept in ``masks``; its vertex and triangle counts, packed into one int64
   (vertices in the high 32 bits, triangles in the low) in ``counts``.
2. ``kdsl.utils.array_scan`` of ``counts``, in place: one scan gives both the vertices'
   and the triangles' output offsets. The last entry, read back, sizes the outputs.
3. ``_emit_surface``, one thread per node again: it writes its edges' vertices and its
   cell's triangles. A triangle's vertex on a neighbour's edge has the index that
   neighbour's scanned offset and mask give, so no per-edge index array is needed.

The case tables are ``kdsl.geometry.marching_cubes_tables``, uploaded once per device.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from kdsl.errors import KdslTypeError, KdslValueError
from kdsl.frontend.api import clamp, func, isfinite, isnan, kernel, lerp, tid
from kdsl.frontend.api import min as kmin
from kdsl.geometry.marching_cubes_tables import (
    CASE_TO_TRI_RANGE,
    TRI_LOCAL_INDICES,
    edge_node_and_axis,
)
from kdsl.ir import types as T
from kdsl.runtime.alloc import empty
from kdsl.runtime.array import array
from kdsl.runtime.device import Device
from kdsl.runtime.launch import launch
from kdsl.types import float32, int32, int64, type_of, vec3
from kdsl.utils import array_scan

#: The most grid nodes a field may have: every edge (three per node) must have an int32
#: index, as Warp's vertex indices are int32.
MAX_NODES = (2**31 - 1) // 3
#: The most triangle indices (three per triangle) one surface may have.
MAX_INDICES = 2**31 - 1
_LOW32 = 0xFFFFFFFF


class MarchingCubesError(KdslValueError):
    """A bad marching cubes argument value: a field shape, dims, a threshold (a
    ``ValueError``, as Warp raises)."""


class MarchingCubesTypeError(KdslTypeError, TypeError):
    """A marching cubes argument of the wrong kind: not a kdsl array, not float32, on
    another device (a ``TypeError``, as Warp raises for the dtype)."""


@func
def _bits3(m: int32) -> int32:
    """How many of the three low bits of ``m`` are set (a node's crossing edges)."""
    return (m & 1) + ((m >> 1) & 1) + ((m >> 2) & 1)


@func
def _inside(field: array(dtype=float32, ndim=3), i: int32, j: int32, k: int32,
            threshold: float32, bit: int32) -> int32:  # fmt: skip
    # ">=" as Warp's case code; a NaN is below every threshold.
    if field[i, j, k] >= threshold:
        return bit
    return 0


@kernel
def _classify_nodes(
    field: array(dtype=float32, ndim=3), threshold: float32, case_ranges: array(dtype=int32),
    counts: array(dtype=int64), masks: array(dtype=int32),
):  # fmt: skip
    i, j, k = tid()
    nx, ny, nz = field.shape[0], field.shape[1], field.shape[2]
    # Past the last node a neighbour is the node itself: that edge then never crosses
    # (both ends agree), so the boundary needs no branch; its cell is dropped below.
    i1 = kmin(i + 1, nx - 1)
    j1 = kmin(j + 1, ny - 1)
    k1 = kmin(k + 1, nz - 1)
    code = (
        _inside(field, i, j, k, threshold, 1) | _inside(field, i1, j, k, threshold, 2)
        | _inside(field, i1, j1, k, threshold, 4) | _inside(field, i, j1, k, threshold, 8)
        | _inside(field, i, j, k1, threshold, 16) | _inside(field, i1, j, k1, threshold, 32)
        | _inside(field, i1, j1, k1, threshold, 64) | _inside(field, i, j1, k1, threshold, 128)
    )  # fmt: skip
    # Corners 1, 3 and 4 are the node's +x, +y and +z neighbours.
    inside = code & 1
    edges = (((code >> 1) & 1) ^ inside) | ((((code >> 3) & 1) ^ inside) << 1)
    edges = edges | ((((code >> 4) & 1) ^ inside) << 2)
    if i1 == i or j1 == j or k1 == k:
        code = 0  # the last node along an axis starts no cell
    tris = (case_ranges[code + 1] - case_ranges[code]) // 3
    node = (i * ny + j) * nz + k
    counts[node] = (int64(_bits3(edges)) << int64(32)) | int64(tris)
    masks[node] = edges | (code << 3)


@func
def _node_position(lower: vec3, delta: vec3, i: int32, j: int32, k: int32) -> vec3:
    return lower + vec3(float32(i) * delta[0], float32(j) * delta[1], float32(k) * delta[2])


@func
def edge_fraction(a: float32, b: float32, threshold: float32) -> float32:
    """Where ``threshold`` crosses the edge from value ``a`` to value ``b``, from 0 at
    ``a`` to 1 at ``b``: Warp's ``clamp((threshold - a) / (b - a), 0, 1)``. Where that
    is NaN (an infinite or NaN end) the vertex goes to the finite end if one end is
    finite, else to the middle (Warp's answer there differs between its devices)."""
    t = clamp((threshold - a) / (b - a), 0.0, 1.0)
    if isnan(t):
        t = 0.5
        if isfinite(a) and not isfinite(b):
            t = 0.0
        elif isfinite(b) and not isfinite(a):
            t = 1.0
    return t


@func
def _edge_vertex(a: float32, b: float32, threshold: float32, p: vec3, q: vec3) -> vec3:
    return lerp(p, q, edge_fraction(a, b, threshold))


@func
def _vertex_index(offsets: array(dtype=int64), masks: array(dtype=int32), node: int32,
                  axis: int32) -> int32:  # fmt: skip
    """The index of the vertex on ``node``'s edge along ``axis`` (which crosses)."""
    m = masks[node]
    first = int32(offsets[node] >> int64(32)) - _bits3(m)
    return first + _bits3(m & ((1 << axis) - 1))


@kernel
def _emit_surface(
    field: array(dtype=float32, ndim=3), threshold: float32, lower: vec3, delta: vec3,
    case_ranges: array(dtype=int32), tri_edges: array(dtype=int32),
    offsets: array(dtype=int64), masks: array(dtype=int32),
    verts: array(dtype=vec3), indices: array(dtype=int32),
):  # fmt: skip
    i, j, k = tid()
    ny, nz = field.shape[1], field.shape[2]
    node = (i * ny + j) * nz + k
    m = masks[node]
    if m != 0:
        end = offsets[node]
        v = int32(end >> int64(32)) - _bits3(m)
        a = field[i, j, k]
        p = _node_position(lower, delta, i, j, k)
        if m & 1:
            q = _node_position(lower, delta, i + 1, j, k)
            verts[v] = _edge_vertex(a, field[i + 1, j, k], threshold, p, q)
            v += 1
        if m & 2:
            q = _node_position(lower, delta, i, j + 1, k)
            verts[v] = _edge_vertex(a, field[i, j + 1, k], threshold, p, q)
            v += 1
        if m & 4:
            q = _node_position(lower, delta, i, j, k + 1)
            verts[v] = _edge_vertex(a, field[i, j, k + 1], threshold, p, q)
        code = m >> 3
        first = case_ranges[code]
        last = case_ranges[code + 1]
        # The low half of the inclusive scan ends after this cell's triangles.
        out = 3 * int32(end & int64(_LOW32)) - (last - first)
        for e in range(first, last):
            # A packed edge: its start node's offset from this node (x, y, z bits) and
            # its axis (bits 3-4).
            c = tri_edges[e]
            nb = node + (c & 1) * ny * nz + ((c >> 1) & 1) * nz + ((c >> 2) & 1)
            indices[out + e - first] = _vertex_index(offsets, masks, nb, c >> 3)


def _packed_edges() -> np.ndarray:
    packed = []
    for e in range(12):
        dx, dy, dz, axis = edge_node_and_axis(e)
        packed.append(dx | dy << 1 | dz << 2 | axis << 3)
    return np.array([packed[e] for e in TRI_LOCAL_INDICES], dtype=np.int32)


_TABLES: dict[str, tuple[array, array]] = {}


def case_tables(device: Device) -> tuple[array, array]:
    """``(case_ranges, tri_edges)`` on ``device``: ``CASE_TO_TRI_RANGE``, and each
    table edge packed as its start node's offset bits and axis (uploaded once)."""
    tables = _TABLES.get(device.alias)
    if tables is None:
        ranges = array(np.array(CASE_TO_TRI_RANGE, dtype=np.int32), dtype=int32, device=device)
        edges = array(_packed_edges(), dtype=int32, device=device)
        tables = _TABLES[device.alias] = (ranges, edges)
    return tables


def check_field(field: Any) -> tuple[int, int, int]:
    """The node counts of ``field``, a 3-d float32 kdsl array of at least 2 nodes per
    axis and at most ``MAX_NODES`` nodes; else a marching cubes error saying why."""
    if not isinstance(field, array):
        raise MarchingCubesTypeError(
            f"marching cubes field must be a 3-d kdsl.array of float32, not {type(field).__name__}"
        )
    if field.ndim != 3:
        raise MarchingCubesError(
            f"marching cubes field must be a 3-d array, not one of shape {field.shape}"
        )
    if type_of(field.dtype) != T.F32:
        raise MarchingCubesTypeError(
            f"marching cubes field must hold float32 values, not {type_of(field.dtype)}"
        )
    shape = tuple(field.shape)
    check_dims(*shape)
    if min(shape) < 2:
        raise MarchingCubesError(f"marching cubes field needs at least 2 nodes on each axis "
                                 f"(one cell), not shape {shape}")  # fmt: skip
    return shape


def check_dims(nx: int, ny: int, nz: int) -> None:
    """Refuse node counts whose edges overflow Warp's int32 vertex indices."""
    if nx * ny * nz > MAX_NODES:
        raise MarchingCubesError(
            f"marching cubes grid of {nx} x {ny} x {nz} nodes is too large: its edges need "
            f"int32 indices, so at most {MAX_NODES} nodes"
        )


def check_threshold(threshold: Any) -> np.float32:
    """``threshold`` as float32 (Warp's conversion), refusing NaN and non-numbers."""
    if isinstance(threshold, bool) or not isinstance(threshold, int | float | np.number):
        raise MarchingCubesTypeError(
            f"marching cubes threshold must be a number, not {threshold!r}"
        )
    if math.isnan(float(threshold)):
        raise MarchingCubesError("marching cubes threshold is NaN: no surface is defined")
    return np.float32(threshold)


class Scratch:
    """The per-node buffers of one extraction, kept by a reusable context so that
    repeated extractions of same-sized fields do not allocate them again."""

    def __init__(self, nodes: int, device: Device) -> None:
        self.nodes = nodes
        self.device = device
        self.counts = empty(nodes, dtype=int64, device=device)
        self.masks = empty(nodes, dtype=int32, device=device)

    def fits(self, nodes: int, device: Device) -> bool:
        """Whether these buffers serve a field of ``nodes`` nodes on ``device``."""
        return self.nodes == nodes and self.device == device


def extract_surface(
    field: array, threshold: Any, lower: Any, delta: Any, *, scratch: Scratch | None = None,
    backend: Any = None,
) -> tuple[array, array]:  # fmt: skip
    """``(verts, indices)`` of the ``threshold`` iso-surface of ``field`` (checked with
    ``check_field`` / ``check_threshold``): vec3 vertices at ``lower + index * delta``
    interpolated along grid edges, three int32 indices per triangle, both new arrays on
    the field's device. ``scratch`` reuses buffers; ``backend`` picks the kernels'
    backend (``"interp"`` in tests)."""
    nx, ny, nz = check_field(field)
    thr = check_threshold(threshold)
    device = field.device
    nodes = nx * ny * nz
    if scratch is None or not scratch.fits(nodes, device):
        scratch = Scratch(nodes, device)
    ranges, tri_edges = case_tables(device)
    counts, masks = scratch.counts, scratch.masks
    launch(_classify_nodes, dim=(nx, ny, nz), inputs=[field, thr, ranges, counts, masks],
           device=device, backend=backend)  # fmt: skip
    array_scan(counts, counts, inclusive=True)
    total = int(counts[nodes - 1 :].numpy()[0])  # the one read back: the output sizes
    num_verts, num_tris = total >> 32, total & _LOW32
    if 3 * num_tris > MAX_INDICES:
        raise MarchingCubesError(f"marching cubes surface has {num_tris} triangles: more "
                                 f"than int32 indices can address")  # fmt: skip
    verts = empty(num_verts, dtype=vec3, device=device, requires_grad=field.requires_grad)
    indices = empty(3 * num_tris, dtype=int32, device=device)
    if num_verts:
        launch(_emit_surface, dim=(nx, ny, nz), device=device, backend=backend,
               inputs=[field, thr, vec3(*lower), vec3(*delta), ranges, tri_edges, counts, masks,
                       verts, indices])  # fmt: skip
    return verts, indices
