"""Test helpers for volume sampling: grids made with kdsl's NanoVDB builder, a kernel id
for them without ``kdsl.Volume`` (``GridHandle``), and a NumPy float64 reference of
``volume_sample``/``volume_lookup`` over a dense copy of the grid's values."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import kdsl as wp
from kdsl.geometry.nanovdb.builder import build_grid, leaves_from_voxels
from kdsl.geometry.nanovdb.layout import GridType
from kdsl.geometry.nanovdb.reader import read_grids
from kdsl.geometry.volume_record import make_volume_record


class GridHandle:
    """A grid's words on a device and its records: ``.id`` for kernels."""

    def __init__(self, data: bytes, device: str = "cpu", tiles: dict | None = None) -> None:
        self.info = read_grids(data)[0]
        raw = np.frombuffer(self.info.data, np.uint8).copy()
        for origin, value in (tiles or {}).items():
            set_lower_tile(self.info, raw, origin, value)
        self.words = wp.array(raw.view(np.uint32), dtype=wp.uint32, device=device)
        self.record = make_volume_record(self, self.words, self.info, device)
        self.id = self.record.id


def set_lower_tile(info, raw: np.ndarray, origin: tuple, value) -> None:
    """Give the 8^3 region at ``origin`` (a lower-node table slot without a leaf) the tile
    value ``value``, in the grid bytes ``raw``."""
    lay = info.layout
    node_origin = np.array(origin) & ~127
    for n in range(info.lower_count):
        at = info.lower_offset + n * lay.lower_size
        bbox_min = np.frombuffer(raw[at : at + 12].tobytes(), np.int32)
        if np.array_equal(bbox_min & ~127, node_origin):
            break
    else:
        raise AssertionError(f"no lower node holds {origin}")
    x, y, z = (np.array(origin) & 127) >> 3
    slot = (x << 8) | (y << 4) | z
    mask = np.frombuffer(raw[at + 544 : at + 1056].tobytes(), np.uint32)
    assert not (mask[slot >> 5] >> (slot & 31)) & 1, "the region has a leaf"
    entry = at + lay.lower_off_table + lay.table_stride * slot
    v = np.asarray(value, lay.value_dtype).tobytes()
    raw[entry : entry + len(v)] = np.frombuffer(v, np.uint8)


@dataclass
class DenseGrid:
    """The values of a grid over the box ``[lo, lo + values.shape[:3])``; every voxel
    outside the box is ``background``."""

    lo: np.ndarray
    values: np.ndarray
    background: np.ndarray

    def lookup(self, ijk: np.ndarray) -> np.ndarray:
        """Float64 values at integer voxels ``ijk`` (N, 3)."""
        rel = ijk - self.lo
        inside = np.all((rel >= 0) & (rel < self.values.shape[:3]), axis=1)
        out = np.empty((len(ijk), *self.values.shape[3:]), np.float64)
        out[...] = self.background
        r = rel[inside]
        out[inside] = self.values[r[:, 0], r[:, 1], r[:, 2]]
        return out

    def closest(self, uvw: np.ndarray) -> np.ndarray:
        """Warp's CLOSEST: each coordinate rounded half away from zero."""
        r = np.sign(uvw) * np.floor(np.abs(uvw.astype(np.float64)) + 0.5)
        return self.lookup(r.astype(np.int64))

    def linear(self, uvw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Trilinear value and gradient (by ``uvw``; one row per component for vectors)."""
        p = uvw.astype(np.float64)
        base = np.floor(p)
        f = p - base
        val = 0.0
        grad = [0.0, 0.0, 0.0]
        for corner in np.ndindex(2, 2, 2):
            c = np.array(corner)
            v = self.lookup(base.astype(np.int64) + c)
            w = np.where(c == 1, f, 1.0 - f)  # (N, 3) per-axis weights
            s = np.where(c == 1, 1.0, -1.0)
            tail = (slice(None),) + (None,) * (v.ndim - 1)
            val = val + (w[:, 0] * w[:, 1] * w[:, 2])[tail] * v
            for a in range(3):
                others = np.prod(np.delete(w, a, axis=1), axis=1)
                grad[a] = grad[a] + (s[a] * others)[tail] * v
        return val, np.stack(grad, axis=-1)


#: The lower-node tile ``sparse_float_grid``'s grid has (pass it to ``GridHandle``).
TILE = {(0, 120, 0): 5.0}


def sparse_float_grid(rng: np.random.Generator, background: float = 0.25):
    """A float32 grid of random active voxels in two root regions (negative x) and
    across leaf and lower-node boundaries, with some leaves only partly active; its
    bytes and the dense reference."""
    lo = np.array([-12, 118, -5])
    shape = (30, 22, 19)
    values = rng.standard_normal(shape).astype(np.float32)
    keep = rng.random(shape) < 0.7
    # Whole 8^3 regions without leaves: one at the background, one at a tile value
    # (``TILE``, set by ``GridHandle(..., tiles=TILE)``) in the lower node at the origin.
    keep[:8, :, :8] = False
    keep[12:20, 2:10, 5:13] = False
    values[~keep] = background
    values[12:20, 2:10, 5:13] = TILE[0, 120, 0]
    ijk = np.argwhere(keep) + lo
    data = build_grid(leaves_from_voxels(ijk, values[keep], np.float32(background)),
                      GridType.FLOAT, np.float32(background), np.eye(3), (0.0, 0.0, 0.0))  # fmt: skip
    return data, DenseGrid(lo, values.astype(np.float64), np.float64(background))


def typed_grid(rng: np.random.Generator, grid_type: GridType, dtype, shape: tuple, bg):
    """A grid of ``grid_type`` with every voxel of a small box active (random values of
    NumPy ``dtype`` and value ``shape``); its bytes and the dense reference."""
    lo = np.array([3, -9, 60])
    box = (11, 10, 9)
    if np.issubdtype(dtype, np.integer):
        values = rng.integers(-1000, 1000, (*box, *shape)).astype(dtype)
    else:
        values = rng.standard_normal((*box, *shape)).astype(dtype)
    ijk = np.argwhere(np.ones(box, bool)) + lo
    bgv = np.broadcast_to(np.asarray(bg, dtype=dtype), shape).copy()
    data = build_grid(leaves_from_voxels(ijk, values.reshape(-1, *shape), bgv), grid_type, bgv,
                      np.eye(3), (0.0, 0.0, 0.0))  # fmt: skip
    return data, DenseGrid(lo, values.astype(np.float64), bgv.astype(np.float64))


def sample_points(rng: np.random.Generator, dense: DenseGrid, n: int) -> np.ndarray:
    """Points in and around the dense box (a margin of 3 voxels), with some on leaf
    boundaries (coordinates whose floor is 7 mod 8) and some at integers."""
    lo = dense.lo - 3
    hi = dense.lo + np.array(dense.values.shape[:3]) + 3
    p = rng.uniform(lo, hi, (n, 3))
    edge = rng.random(n) < 0.3
    p[edge] = np.floor(p[edge] / 8) * 8 + 7 + rng.random((edge.sum(), 3))
    p[: n // 10] = np.round(p[: n // 10])
    return p.astype(np.float32)
