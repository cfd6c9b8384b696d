"""Surface nets on a dense float32 field (Warp 1.19's ``warp.geometry.IsoSurfaceNets``),
as kdsl kernels on the field's device.

One vertex per pass of the surface through a cell (at the mean of its edge crossings),
one quad (or two triangles) around each grid edge the surface crosses, joining the
vertices of the edge's four cells: OpenVDB's uniform volume-to-mesh, with its tables
(``kdsl.geometry.surface_nets_tables``), so the mesh is Warp's index for index. Three
kernels over the cells and one scan:

1. ``_classify_cells``: a cell's sign configuration (corrected where a face is
   ambiguous and its neighbour across that face agrees), which of its three lower
   edges cross, the edge groups that make a vertex (groups with an edge that has four
   cells), packed into ``flags``; its vertex and quad counts packed into one int64
   (vertices high, quads low) for one ``kdsl.utils.array_scan``, whose last entry, read
   back, sizes the outputs.
2. ``_cell_vertices``: each vertex at the mean of its group's crossing points.
3. ``_cell_faces``: the quads around the cell's crossing lower edges.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from kdsl.frontend.api import cw_mul, func, kernel, tid, where
from kdsl.geometry import surface_nets_tables as tables
from kdsl.geometry.iso_surface import Bounds, IsoSurfaceBase, resolve_domain_bounds
from kdsl.geometry.marching_cubes import (
    MarchingCubesError,
    Scratch,
    check_field,
    check_threshold,
    edge_fraction,
)
from kdsl.runtime.alloc import empty
from kdsl.runtime.array import array
from kdsl.runtime.device import Device
from kdsl.runtime.launch import launch
from kdsl.types import float32, int32, int64, vec3
from kdsl.utils import array_scan

#: The face types ``topology`` may name.
TOPOLOGIES = ("triangle", "quad")
_LOW32 = 0xFFFFFFFF
# flags: bits 0-7 the corrected signs, 8 corner 0 inside (raw), 9-11 the lower x/y/z
# edges cross (raw signs), 12-15 the edge groups that make a vertex.
_INSIDE, _XEDGE, _YEDGE, _ZEDGE, _GROUPS = 0x100, 0x200, 0x400, 0x800, 12


@func
def _signs(field: array(dtype=float32, ndim=3), i: int32, j: int32, k: int32,
           threshold: float32) -> int32:  # fmt: skip
    """Bit ``c`` set when OpenVDB corner ``c`` is below the threshold (a NaN is not)."""
    s = 0
    if field[i, j, k] < threshold:
        s = s | 1
    if field[i + 1, j, k] < threshold:
        s = s | 2
    if field[i + 1, j, k + 1] < threshold:
        s = s | 4
    if field[i, j, k + 1] < threshold:
        s = s | 8
    if field[i, j + 1, k] < threshold:
        s = s | 16
    if field[i + 1, j + 1, k] < threshold:
        s = s | 32
    if field[i + 1, j + 1, k + 1] < threshold:
        s = s | 64
    if field[i, j + 1, k + 1] < threshold:
        s = s | 128
    return s


@func
def _bits4(m: int32) -> int32:
    return (m & 1) + ((m >> 1) & 1) + ((m >> 2) & 1) + ((m >> 3) & 1)


@kernel
def _classify_cells(
    field: array(dtype=float32, ndim=3), threshold: float32, ambiguous: array(dtype=int32),
    groups_table: array(dtype=int32), edges: array(dtype=int32),
    flags: array(dtype=int32), counts: array(dtype=int64),
):  # fmt: skip
    ci, cj, ck = tid()
    nx, ny, nz = field.shape[0] - 1, field.shape[1] - 1, field.shape[2] - 1
    cell = (ci * ny + cj) * nz + ck
    signs = _signs(field, ci, cj, ck, threshold)
    f = 0
    points = 0
    quads = 0
    if signs != 0 and signs != 255:
        inside = signs & 1
        xedge = inside != ((signs >> 1) & 1)
        yedge = inside != ((signs >> 4) & 1)
        zedge = inside != ((signs >> 3) & 1)
        f = inside * _INSIDE
        if xedge:
            f = f | _XEDGE
        if yedge:
            f = f | _YEDGE
        if zedge:
            f = f | _ZEDGE
        # An ambiguous configuration flips when the neighbour across the deciding face
        # is ambiguous across the same face (OpenVDB's correctCellSigns); faces 1-6 are
        # -z, +x, +z, -x, -y, +y, complementary in pairs.
        face = ambiguous[signs]
        if face != 0:
            ni, nj, nk = ci, cj, ck
            if face == 1:
                nk = ck - 1
            elif face == 2:
                ni = ci + 1
            elif face == 3:
                nk = ck + 1
            elif face == 4:
                ni = ci - 1
            elif face == 5:
                nj = cj - 1
            else:
                nj = cj + 1
            other = 11 - face
            if face <= 4:
                other = (face + 1) % 4 + 1
            # Nested: the neighbour is read only when it exists.
            if ni >= 0 and ni < nx and nj >= 0 and nj < ny and nk >= 0 and nk < nz:  # noqa: SIM102
                if ambiguous[_signs(field, ni, nj, nk, threshold)] == other:
                    signs = (~signs) & 255
        # A grid-boundary edge has fewer than four cells, so no quad: a group makes a
        # vertex only if one of its edges lies strictly inside the grid across its axis.
        have = 0
        if ci > 0:
            have = have | 1
        if ci + 1 < nx:
            have = have | 2
        if cj > 0:
            have = have | 4
        if cj + 1 < ny:
            have = have | 8
        if ck > 0:
            have = have | 16
        if ck + 1 < nz:
            have = have | 32
        groups = 0
        for e in range(12):
            g = groups_table[signs * 13 + 1 + e]
            need = edges[e] >> 5
            if g != 0 and (have & need) == need:
                groups = groups | (1 << (g - 1))
        f = f | signs | (groups << _GROUPS)
        points = _bits4(groups)
        if xedge and cj > 0 and ck > 0:
            quads += 1
        if yedge and ci > 0 and ck > 0:
            quads += 1
        if zedge and ci > 0 and cj > 0:
            quads += 1
    flags[cell] = f
    counts[cell] = (int64(points) << int64(32)) | int64(quads)


@kernel
def _cell_vertices(
    field: array(dtype=float32, ndim=3), threshold: float32, groups_table: array(dtype=int32),
    edges: array(dtype=int32), flags: array(dtype=int32), offsets: array(dtype=int64),
    lower: vec3, delta: vec3, verts: array(dtype=vec3),
):  # fmt: skip
    ci, cj, ck = tid()
    ny, nz = field.shape[1] - 1, field.shape[2] - 1
    cell = (ci * ny + cj) * nz + ck
    f = flags[cell]
    groups = f >> _GROUPS
    if groups != 0:
        signs = f & 255
        first = int32(offsets[cell] >> int64(32)) - _bits4(groups)
        for g in range(1, groups_table[signs * 13] + 1):
            if (groups >> (g - 1)) & 1:
                s = vec3(0.0, 0.0, 0.0)
                n = 0
                for e in range(12):
                    if groups_table[signs * 13 + 1 + e] == g:
                        # A packed edge: its lower corner's offset (bits 0-2), axis (3-4).
                        p = edges[e]
                        axis = (p >> 3) & 3
                        ux, uy, uz = (
                            where(axis == 0, 1, 0),
                            where(axis == 1, 1, 0),
                            where(axis == 2, 1, 0),
                        )
                        i, j, k = ci + (p & 1), cj + ((p >> 1) & 1), ck + ((p >> 2) & 1)
                        a = vec3(float32(p & 1), float32((p >> 1) & 1), float32((p >> 2) & 1))
                        u = vec3(float32(ux), float32(uy), float32(uz))
                        va = field[i, j, k]
                        vb = field[i + ux, j + uy, k + uz]
                        s = s + a + u * edge_fraction(va, vb, threshold)
                        n += 1
                if n > 1:
                    s = s * (1.0 / float32(n))
                rank = _bits4(groups & ((1 << (g - 1)) - 1))
                local = vec3(float32(ci) + s[0], float32(cj) + s[1], float32(ck) + s[2])
                verts[first + rank] = lower + cw_mul(local, delta)


@func
def _vertex(flags: array(dtype=int32), groups_table: array(dtype=int32),
            offsets: array(dtype=int64), cell: int32, column: int32) -> int32:  # fmt: skip
    """The index of ``cell``'s vertex on its edge ``column`` (a table column, 1-12)."""
    f = flags[cell]
    groups = f >> _GROUPS
    g = groups_table[(f & 255) * 13 + column]
    first = int32(offsets[cell] >> int64(32)) - _bits4(groups)
    return first + _bits4(groups & ((1 << (g - 1)) - 1))


@func
def _write_quad(
    indices: array(dtype=int32), quads: bool, q: int32, flags: array(dtype=int32),
    groups_table: array(dtype=int32), offsets: array(dtype=int64), cell: int32, da: int32,
    db: int32, columns: int32, reverse: bool,
):  # fmt: skip
    """Write quad ``q`` around a crossing edge: the vertices of ``cell``, ``cell - da``,
    ``cell - da - db`` and ``cell - db`` on the edge (their table columns: 4 bits each
    of ``columns``, first cell lowest), as 4 indices or two triangles split along the
    first diagonal, reversed when ``reverse``."""
    v0 = _vertex(flags, groups_table, offsets, cell, columns & 15)
    v1 = _vertex(flags, groups_table, offsets, cell - da, (columns >> 4) & 15)
    v2 = _vertex(flags, groups_table, offsets, cell - da - db, (columns >> 8) & 15)
    v3 = _vertex(flags, groups_table, offsets, cell - db, columns >> 12)
    if reverse:
        v0, v1, v2, v3 = v3, v2, v1, v0
    if quads:
        indices[4 * q] = v0
        indices[4 * q + 1] = v1
        indices[4 * q + 2] = v2
        indices[4 * q + 3] = v3
    else:
        indices[6 * q] = v0
        indices[6 * q + 1] = v1
        indices[6 * q + 2] = v2
        indices[6 * q + 3] = v0
        indices[6 * q + 4] = v2
        indices[6 * q + 5] = v3


@kernel
def _cell_faces(
    flags: array(dtype=int32), groups_table: array(dtype=int32), offsets: array(dtype=int64),
    ny: int32, nz: int32, quads: bool, indices: array(dtype=int32),
):  # fmt: skip
    ci, cj, ck = tid()
    cell = (ci * ny + cj) * nz + ck
    f = flags[cell]
    if (f & (_XEDGE | _YEDGE | _ZEDGE)) != 0:
        inside = (f & _INSIDE) != 0
        x = (f & _XEDGE) != 0 and cj > 0 and ck > 0
        y = (f & _YEDGE) != 0 and ci > 0 and ck > 0
        z = (f & _ZEDGE) != 0 and ci > 0 and cj > 0
        # The scan's low half ends after this cell's quads.
        q = int32(offsets[cell] & int64(_LOW32)) - where(x, 1, 0) - where(y, 1, 0) - where(z, 1, 0)
        dx, dy, dz = ny * nz, nz, 1
        # OpenVDB's quads, wound counter-clockwise seen from outside a field that is
        # negative inside; each cell's table column is a hex digit, the first cell's lowest.
        if x:
            _write_quad(indices, quads, q, flags, groups_table, offsets, cell, dy, dz, 0x3751,
                        not inside)  # fmt: skip
            q += 1
        if y:
            _write_quad(indices, quads, q, flags, groups_table, offsets, cell, dz, dx, 0xABC9,
                        not inside)  # fmt: skip
            q += 1
        if z:
            _write_quad(indices, quads, q, flags, groups_table, offsets, cell, dy, dx, 0x2684,
                        inside)  # fmt: skip


def _packed_edges() -> np.ndarray:
    """Per edge: its lower corner's offset (bits 0-2), axis (3-4) and the grid sides its
    cell needs for the edge to have four cells (bits 5-10: x-lo, x-hi, y-lo, y-hi, z-lo,
    z-hi), from the edge's position across its two other axes."""
    packed = []
    for a, b in tables.EDGE_TO_CORNERS:
        lo, hi = tables.CORNER_OFFSETS[a], tables.CORNER_OFFSETS[b]
        axis = next(d for d in range(3) if lo[d] != hi[d])
        need = 0
        for d in range(3):
            if d != axis:
                need |= 1 << (2 * d + lo[d])
        packed.append(lo[0] | lo[1] << 1 | lo[2] << 2 | axis << 3 | need << 5)
    return np.array(packed, dtype=np.int32)


_TABLES: dict[str, tuple[array, array, array]] = {}


def _tables(device: Device) -> tuple[array, array, array]:
    """``(ambiguous faces, edge groups, packed edges)`` on ``device``, uploaded once."""
    if device.alias not in _TABLES:
        _TABLES[device.alias] = (
            array(np.array(tables.AMBIGUOUS_FACE, np.int32), dtype=int32, device=device),
            array(np.array(tables.EDGE_GROUPS, np.int32).ravel(), dtype=int32, device=device),
            array(_packed_edges(), dtype=int32, device=device),
        )
    return _TABLES[device.alias]


def check_topology(topology: Any) -> bool:
    """Whether ``topology`` asks for quads (``"quad"``) rather than triangles."""
    if topology not in TOPOLOGIES:
        raise MarchingCubesError(f"topology must be 'triangle' or 'quad', not {topology!r}")
    return topology == "quad"


def extract_nets(
    field: array, threshold: Any, lower: Any, delta: Any, topology: str = "triangle", *,
    scratch: Scratch | None = None, backend: Any = None,
) -> tuple[array, array]:  # fmt: skip
    """``(verts, indices)`` of the surface nets of ``field`` at ``threshold``: node
    ``(i, j, k)`` at ``lower + (i, j, k) * delta``, three indices per triangle (or four
    per quad), new arrays on the field's device. ``backend`` picks the kernels' backend
    (``"interp"`` in tests)."""
    nx, ny, nz = check_field(field)
    quads = check_topology(topology)
    thr = check_threshold(threshold)
    device = field.device
    cells = (nx - 1) * (ny - 1) * (nz - 1)
    if scratch is None or not scratch.fits(field.size, device):
        scratch = Scratch(field.size, device)
    flags, counts = scratch.masks[:cells], scratch.counts[:cells]
    ambiguous, groups, edges = _tables(device)
    dims = (nx - 1, ny - 1, nz - 1)
    launch(_classify_cells, dim=dims, device=device, backend=backend,
           inputs=[field, thr, ambiguous, groups, edges, flags, counts])  # fmt: skip
    array_scan(counts, counts, inclusive=True)
    total = int(counts[cells - 1 :].numpy()[0])  # the one read back: the output sizes
    num_verts, num_quads = total >> 32, total & _LOW32
    per_quad = 4 if quads else 6
    if per_quad * num_quads > 2**31 - 1:
        raise MarchingCubesError(f"surface nets of {num_quads} quads: more indices than "
                                 f"int32 can address")  # fmt: skip
    verts = empty(num_verts, dtype=vec3, device=device, requires_grad=field.requires_grad)
    indices = empty(per_quad * num_quads, dtype=int32, device=device)
    if num_verts:
        launch(_cell_vertices, dim=dims, device=device, backend=backend,
               inputs=[field, thr, groups, edges, flags, counts, vec3(*lower), vec3(*delta),
                       verts])  # fmt: skip
    if num_quads:
        launch(_cell_faces, dim=dims, device=device, backend=backend,
               inputs=[flags, groups, counts, ny - 1, nz - 1, quads, indices])  # fmt: skip
    return verts, indices


class IsoSurfaceNets(IsoSurfaceBase):
    """Surface nets, as ``warp.geometry.IsoSurfaceNets(nx, ny, nz, *, lower=None,
    upper=None, topology="triangle")``: a vertex in each cell the surface passes through
    (one per pass), at the mean of the points where it crosses the cell's edges, and a
    quad around each grid edge it crosses (split into two triangles along its first
    diagonal unless ``topology="quad"``), wound counter-clockwise seen from where the
    field is above the threshold. A surface inside the grid is closed (every edge in two
    faces); one that leaves the grid stops up to a cell short of its boundary.
    A node is inside when its value is below the threshold (a NaN is not)."""

    def __init__(
        self, nx: int, ny: int, nz: int, *, lower: Bounds = None, upper: Bounds = None,
        topology: str = "triangle",
    ) -> None:  # fmt: skip
        check_topology(topology)
        super().__init__(nx, ny, nz, lower=lower, upper=upper)
        #: ``"triangle"`` or ``"quad"``: the faces ``surface`` makes.
        self.topology = topology
        self._scratch: Scratch | None = None

    def surface(self, field: array, threshold: float) -> None:
        """Extract the ``threshold`` iso-surface of ``field`` (shape ``(nx, ny, nz)``)
        into ``verts`` and ``indices`` (faces of ``topology``)."""
        self._check_field_shape(field)
        lower, delta = resolve_domain_bounds(field.shape, self.lower, self.upper)
        if self._scratch is None or not self._scratch.fits(field.size, field.device):
            self._scratch = Scratch(field.size, field.device)
        self.verts, self.indices = extract_nets(field, threshold, lower, delta, self.topology,
                                                scratch=self._scratch)  # fmt: skip

    @classmethod
    def extract(
        cls, field: array, threshold: float = 0.0, *, lower: Bounds = None, upper: Bounds = None,
        topology: str = "triangle",
    ) -> tuple[array, array]:  # fmt: skip
        """``(verts, indices)`` of the ``threshold`` surface nets of ``field`` (a 3-d
        float32 array, at least 2 nodes per axis), on the field's device."""
        shape = check_field(field)
        lo, delta = resolve_domain_bounds(shape, lower, upper)
        return extract_nets(field, threshold, lo, delta, topology)


__all__ = ["IsoSurfaceNets", "extract_nets"]
