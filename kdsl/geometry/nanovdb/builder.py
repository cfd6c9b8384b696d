"""Build NanoVDB grid bytes on the host, vectorized in NumPy.

Every build goes through ``Leaves``: the leaf origins (multiples of 8), which of each
leaf's 512 voxels are active, and their values (the background where inactive). Three
constructors make them: ``leaves_from_dense`` (a dense array, every voxel active, as
``Volume.load_from_numpy`` and ``allocate`` need), ``leaves_from_tiles`` (whole 8^3
tiles, active, at the background value) and ``leaves_from_voxels`` (single active
voxels). ``build_grid`` then writes the tree breadth-first in Warp's order (upper nodes
sorted by their 4096^3 region, lexicographically with x first, then each node's children
in table order, which is x-major too), so tiles and voxels come out in the order
``warp.Volume.get_tiles`` gives them.

What is written, as Warp's builder writes it: no active tiles above the leaves; the
background in every inactive internal-node table slot and inactive leaf voxel; each
leaf's bounding box of its active voxels; node statistics left zero (the grid's
``HAS_MIN_MAX`` flag is off, so readers ignore them). Unlike Warp, kdsl fills in the
checksum and the tree's tile counts (zero) and the name key NanoVDB's tools look up.
Index grids: index 0 is the background; an OnIndex grid numbers its active voxels from 1
in leaf order, an Index grid (Warp's choice for whole tiles) every voxel of its leaves;
feature arrays become blind data (one value per index).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from kdsl.geometry.nanovdb.checksum import grid_checksum
from kdsl.geometry.nanovdb.errors import NanoVDBError
from kdsl.geometry.nanovdb.layout import (
    BLIND_METADATA_SIZE,
    CHECKSUM_DISABLED,
    DATA_ALIGNMENT,
    GRID_NAME_SIZE,
    GRID_OFF_CHECKSUM,
    GRID_OFF_GRID_NAME,
    GRID_OFF_MAP,
    GRID_SIZE,
    LEAF_FLAG_HAS_BBOX,
    LEAF_OFF_INDEX_OFFSET,
    LEAF_OFF_VALUE_MASK,
    LOWER_OFF_CHILD_MASK,
    LOWER_TABLE_COUNT,
    MAGIC_GRID,
    MAGIC_NUMB,
    ROOT_BASE_SIZE,
    TREE_SIZE,
    UPPER_OFF_CHILD_MASK,
    UPPER_TABLE_COUNT,
    WRITE_VERSION,
    GridClass,
    GridFlags,
    GridType,
    ValueLayout,
    make_version,
    value_layout,
)

_INT32_MIN, _INT32_MAX = -(2**31), 2**31 - 1
_CHANNEL_ARRAY = 4  # GridBlindDataClass::ChannelArray


@dataclass
class Leaves:
    """Leaf nodes to build: ``origins`` (L, 3) int64, ``active`` (L, 512) bool with voxel
    ``(i, j, k)`` of a leaf at ``(i & 7) * 64 + (j & 7) * 8 + (k & 7)``, and ``values``
    (L, 512, *value shape) or ``None`` for an index grid."""

    origins: np.ndarray
    active: np.ndarray
    values: np.ndarray | None


def _check_coords(coords: np.ndarray, what: str) -> np.ndarray:
    coords = np.asarray(coords, dtype=np.int64).reshape(-1, 3)
    if coords.size and (coords.min() < _INT32_MIN or coords.max() > _INT32_MAX):
        raise NanoVDBError(f"{what} lie outside NanoVDB's int32 index space")
    return coords


def tree_order(origins: np.ndarray) -> np.ndarray:
    """The permutation putting leaf ``origins`` in breadth-first tree order: by upper
    node (x, y, z of the 4096^3 region), then lower node, then leaf, each x-major."""
    o = origins
    return np.lexsort(tuple((o[:, a] >> s) for s in (3, 7, 12) for a in (2, 1, 0)))


def _unique_rows(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sorted unique rows of multiples of 8 and each row's position among them. Rows are
    packed into one int64 (21 bits per axis of ``row >> 3``) when their span allows:
    sorting one key is many times faster than NumPy's row-wise ``unique``."""
    if len(rows) == 0:
        return rows.reshape(0, 3), np.zeros(0, dtype=np.int64)
    low = rows.min(axis=0)
    cells = (rows - low) >> 3
    if cells.max() >= 1 << 21:
        origins, inverse = np.unique(rows, axis=0, return_inverse=True)
        return origins, inverse.reshape(-1)
    keys = (cells[:, 0] << 42) | (cells[:, 1] << 21) | cells[:, 2]
    unique, inverse = np.unique(keys, return_inverse=True)
    mask = (1 << 21) - 1
    cells = np.stack([unique >> 42, (unique >> 21) & mask, unique & mask], axis=1)
    return (cells << 3) + low, inverse.reshape(-1)


def leaves_from_voxels(coords: np.ndarray, values: np.ndarray | None, background) -> Leaves:
    """Leaves holding the active voxels ``coords`` (N, 3) with ``values`` (N, ...) (a
    repeated voxel keeps its last value), the rest of each leaf at ``background``."""
    coords = _check_coords(coords, "voxel coordinates")
    origins, leaf = _unique_rows(coords & ~7)
    slot = (coords[:, 0] & 7) * 64 + (coords[:, 1] & 7) * 8 + (coords[:, 2] & 7)
    active = np.zeros((len(origins), 512), dtype=bool)
    active[leaf, slot] = True
    leaf_values = None
    if values is not None:
        values = np.asarray(values)
        leaf_values = np.empty((len(origins), 512, *values.shape[1:]), dtype=values.dtype)
        leaf_values[...] = background
        leaf_values[leaf, slot] = values
    return Leaves(origins, active, leaf_values)


def leaves_from_tiles(origins: np.ndarray, background, index: bool = False) -> Leaves:
    """Whole active 8^3 tiles at ``origins`` (multiples of 8, repeats allowed), every
    voxel at ``background`` (or none for an index grid)."""
    origins = _unique_rows(_check_coords(origins, "tile coordinates") & ~7)[0]
    values = None
    if not index:
        bg = np.asarray(background)
        values = np.broadcast_to(bg, (len(origins), 512, *bg.shape))
    return Leaves(origins, np.ones((len(origins), 512), dtype=bool), values)


def leaves_from_dense(array: np.ndarray, origin: Sequence[int], background) -> Leaves:
    """Every voxel of a dense ``array`` (X, Y, Z, ...) active, voxel ``[0, 0, 0]`` at index
    ``origin``; the array is padded to whole tiles with ``background``."""
    array = np.asarray(array)
    dims = [math.ceil(n / 8) * 8 for n in array.shape[:3]]
    if dims != list(array.shape[:3]):
        padded = np.empty((*dims, *array.shape[3:]), dtype=array.dtype)
        padded[...] = background
        padded[: array.shape[0], : array.shape[1], : array.shape[2]] = array
        array = padded
    tx, ty, tz = dims[0] // 8, dims[1] // 8, dims[2] // 8
    tail = array.shape[3:]
    extra = tuple(range(6, 6 + len(tail)))
    tiles = array.reshape(tx, 8, ty, 8, tz, 8, *tail).transpose(0, 2, 4, 1, 3, 5, *extra)
    grid = np.stack(np.meshgrid(np.arange(tx), np.arange(ty), np.arange(tz), indexing="ij"), -1)
    grid = grid.reshape(-1, 3)
    origins = _check_coords(grid * 8 + np.asarray(origin, dtype=np.int64),
                            "the array's voxel coordinates")  # fmt: skip
    # Gather the tiles in the tree's order: one copy, and build_grid need not reorder.
    order = tree_order(origins)
    ix, iy, iz = grid[order].T
    values = tiles[ix, iy, iz].reshape(len(order), 512, *tail)
    origins = origins[order]
    return Leaves(origins, np.ones((len(origins), 512), dtype=bool), values)


@dataclass(frozen=True)
class Feature:
    """A feature array (blind data) for an index grid: one value per index."""

    name: str
    values: np.ndarray
    grid_type: GridType


def _align(n: int) -> int:
    return -(-n // DATA_ALIGNMENT) * DATA_ALIGNMENT


def _groups(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For sorted rows ``keys``, each row's group number and each group's first row."""
    new = np.ones(len(keys), dtype=bool)
    new[1:] = (keys[1:] != keys[:-1]).any(axis=1)
    return np.cumsum(new) - 1, np.flatnonzero(new)


def _slot(origins: np.ndarray, child_log2: int, dim_log2: int) -> np.ndarray:
    """Each child's table slot in its parent: x-major over the parent's children."""
    c = (origins >> child_log2) & ((1 << dim_log2) - 1)
    return (c[:, 0] << (2 * dim_log2)) | (c[:, 1] << dim_log2) | c[:, 2]


def _leaf_bboxes(leaves: Leaves) -> tuple[np.ndarray, np.ndarray]:
    """Each leaf's inclusive bounding box of its active voxels (its origin when none)."""
    lo, hi = np.zeros((len(leaves.active), 3), np.int64), np.full((len(leaves.active), 3), 7)
    partial = np.flatnonzero(~leaves.active.all(axis=1))  # full leaves span 0..7
    cube = leaves.active[partial].reshape(-1, 8, 8, 8)
    for axis in range(3):
        occupied = cube.any(axis=tuple(a for a in (1, 2, 3) if a != axis + 1))
        lo[partial, axis] = occupied.argmax(axis=1)
        hi[partial, axis] = np.where(occupied.any(axis=1), 7 - occupied[:, ::-1].argmax(axis=1), 0)
    return leaves.origins + lo, leaves.origins + hi


def _bytes_of(value, lay: ValueLayout) -> np.ndarray:
    if lay.is_index:
        return np.zeros(8, np.uint8)
    v = np.asarray(value, dtype=lay.value_dtype).reshape(lay.value_shape)
    return np.frombuffer(v.tobytes(), np.uint8)


class _Writer:
    """Writes fields into a grid's byte buffer."""

    def __init__(self, size: int) -> None:
        self.buf = np.zeros(size, dtype=np.uint8)

    def put(self, offset: int, dtype: str, values) -> None:
        raw = np.ascontiguousarray(np.asarray(values, dtype=dtype)).view(np.uint8).reshape(-1)
        self.buf[offset : offset + raw.size] = raw

    def nodes(self, begin: int, count: int, size: int) -> np.ndarray:
        return self.buf[begin : begin + count * size].reshape(count, size)


def _write_internal(w: _Writer, nodes: np.ndarray, child_of: np.ndarray, child_abs: np.ndarray,
                    slots: np.ndarray, node_abs: np.ndarray, table: tuple[int, int, int],
                    mask_off: int, fill: np.ndarray) -> None:  # fmt: skip
    """Child masks and tables of internal nodes: ``fill`` everywhere, child offsets at
    the children's slots."""
    table_off, count, stride = table
    tables = nodes[:, table_off : table_off + count * stride].reshape(len(nodes), count, stride)
    tables[:, :, : fill.size] = fill
    rel = (child_abs - node_abs[child_of]).astype("<i8")
    tables[child_of, slots, :8] = rel.view(np.uint8).reshape(-1, 8)
    masks = np.zeros((len(nodes), count), dtype=bool)
    masks[child_of, slots] = True
    nodes[:, mask_off : mask_off + count // 8] = np.packbits(masks, axis=1, bitorder="little")


def _bbox_rows(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    return np.concatenate([lo, hi], axis=1).astype("<i4")


def build_grid(
    leaves: Leaves,
    grid_type: GridType,
    background,
    index_to_world: np.ndarray,
    translation: Sequence[float],
    name: str = "",
    grid_class: GridClass | None = None,
    features: Sequence[Feature] = (),
    checksum: bool = True,
) -> bytes:
    """The bytes of a NanoVDB grid of ``grid_type`` holding ``leaves``, with ``world =
    index_to_world @ index + translation`` and the given root ``background``; with
    ``checksum=False`` the checksum is left disabled (all ones), as Warp leaves it in
    the grids it builds in memory."""
    lay = value_layout(grid_type)
    assert lay is not None, grid_type
    raw_name = name.encode("utf-8")
    if len(raw_name) >= GRID_NAME_SIZE or b"\0" in raw_name:
        raise NanoVDBError(f"grid name {name!r} is longer than 255 bytes or holds a NUL")
    mat = np.asarray(index_to_world, dtype=np.float64).reshape(3, 3)
    try:
        inv = np.linalg.inv(mat)
    except np.linalg.LinAlgError:
        raise NanoVDBError(f"the index-to-world transform {mat.tolist()} is singular") from None
    vec = np.asarray(translation, dtype=np.float64).reshape(3)

    o = leaves.origins
    order = tree_order(o)
    active, values = leaves.active, leaves.values
    if (order != np.arange(len(order))).any():  # dense arrays and tiles often come sorted
        o, active = o[order], active[order]
        values = None if values is None else values[order]
    lower_of, lower_first = _groups(o >> 7)
    upper_of_lower, upper_first = _groups(o[lower_first] >> 12)
    lower_o, upper_o = o[lower_first] & ~127, o[lower_first][upper_first] & ~4095
    n_leaf, n_lower, n_upper = len(o), len(lower_o), len(upper_o)

    root = GRID_SIZE + TREE_SIZE
    upper = root + lay.root_size + n_upper * lay.root_tile_size
    lower = upper + n_upper * lay.upper_size
    leaf = lower + n_lower * lay.lower_size
    blind = leaf + n_leaf * lay.leaf_size
    data_at, at = [], _align(blind + len(features) * BLIND_METADATA_SIZE)
    for f in features:
        data_at.append(at)
        at = _align(at + f.values.nbytes)
    w = _Writer(at)
    size = at

    # leaves
    counts = active.sum(axis=1)
    lo, hi = _leaf_bboxes(Leaves(o, active, None))
    nodes = w.nodes(leaf, n_leaf, lay.leaf_size)
    nodes[:, :12] = lo.astype("<i4").view(np.uint8).reshape(-1, 12)
    nodes[:, 12:15] = (hi - lo).astype(np.uint8)
    nodes[:, 15] = np.where(counts > 0, LEAF_FLAG_HAS_BBOX, 0)
    nodes[:, LEAF_OFF_VALUE_MASK : LEAF_OFF_VALUE_MASK + 64] = np.packbits(
        active, axis=1, bitorder="little"
    )
    indexed = counts if grid_type == GridType.ONINDEX else np.full(n_leaf, 512)
    if lay.is_index:
        first = 1 + np.concatenate([[0], np.cumsum(indexed)[:-1]]).astype(np.uint64)
        words = np.cumsum(active.reshape(-1, 8, 64).sum(axis=2), axis=1)[:, :7].astype(np.uint64)
        prefix = np.bitwise_or.reduce(words << (np.arange(7, dtype=np.uint64) * 9), axis=1)
        if grid_type == GridType.INDEX:  # every voxel indexed: no prefix sums
            prefix[:] = 0
        index = np.stack([first, prefix], axis=1).astype("<u8")
        nodes[:, LEAF_OFF_INDEX_OFFSET : LEAF_OFF_INDEX_OFFSET + 16] = index.view(np.uint8)
    else:
        table = np.ascontiguousarray(values, dtype=lay.value_dtype).view(np.uint8)
        nodes[:, lay.leaf_off_table : lay.leaf_off_table + 512 * lay.value_size] = table.reshape(
            n_leaf, -1
        )

    # lower and upper internal nodes: bounding boxes of their children's
    fill = _bytes_of(background, lay)
    lower_lo = np.minimum.reduceat(lo, lower_first) if n_leaf else lo
    lower_hi = np.maximum.reduceat(hi, lower_first) if n_leaf else hi
    nodes = w.nodes(lower, n_lower, lay.lower_size)
    nodes[:, :24] = _bbox_rows(lower_lo, lower_hi).view(np.uint8)
    _write_internal(w, nodes, lower_of, leaf + np.arange(n_leaf) * lay.leaf_size, _slot(o, 3, 4),
                    lower + np.arange(n_lower) * lay.lower_size,
                    (lay.lower_off_table, LOWER_TABLE_COUNT, lay.table_stride),
                    LOWER_OFF_CHILD_MASK, fill)  # fmt: skip
    upper_lo = np.minimum.reduceat(lower_lo, upper_first) if n_lower else lower_lo
    upper_hi = np.maximum.reduceat(lower_hi, upper_first) if n_lower else lower_hi
    nodes = w.nodes(upper, n_upper, lay.upper_size)
    nodes[:, :24] = _bbox_rows(upper_lo, upper_hi).view(np.uint8)
    _write_internal(w, nodes, upper_of_lower, lower + np.arange(n_lower) * lay.lower_size,
                    _slot(lower_o, 7, 5), upper + np.arange(n_upper) * lay.upper_size,
                    (lay.upper_off_table, UPPER_TABLE_COUNT, lay.table_stride),
                    UPPER_OFF_CHILD_MASK, fill)  # fmt: skip

    # root and its tiles, one per upper node
    if n_upper:
        bbox_lo, bbox_hi = upper_lo.min(axis=0), upper_hi.max(axis=0)
    else:  # NanoVDB's empty bounding box
        bbox_lo, bbox_hi = np.full(3, _INT32_MAX), np.full(3, _INT32_MIN)
    w.put(root, "<i4", np.concatenate([bbox_lo, bbox_hi]))
    w.put(root + ROOT_BASE_SIZE - 4, "<u4", n_upper)
    w.buf[root + lay.root_off_background : root + lay.root_off_background + fill.size] = fill
    tiles = w.nodes(root + lay.root_size, n_upper, lay.root_tile_size)
    u = upper_o.astype(np.uint64) & np.uint64(0xFFFFFFFF)
    key = ((u[:, 0] >> 12) << 42) | ((u[:, 1] >> 12) << 21) | (u[:, 2] >> 12)
    child = upper + np.arange(n_upper) * lay.upper_size - root
    tiles[:, 0:8] = key.astype("<u8").view(np.uint8).reshape(-1, 8)
    tiles[:, 8:16] = child.astype("<i8").view(np.uint8).reshape(-1, 8)

    # blind data
    for i, (f, off) in enumerate(zip(features, data_at, strict=True)):
        meta = blind + i * BLIND_METADATA_SIZE
        w.put(meta, "<i8", off - meta)
        w.put(meta + 8, "<u8", len(f.values))
        w.put(meta + 16, "<u4", [f.values.itemsize * math.prod(f.values.shape[1:]), 0,
                                 _CHANNEL_ARRAY, int(f.grid_type)])  # fmt: skip
        fname = f.name.encode("utf-8")[: GRID_NAME_SIZE - 1]
        w.buf[meta + 32 : meta + 32 + len(fname)] = np.frombuffer(fname, np.uint8)
        w.buf[off : off + f.values.nbytes] = np.ascontiguousarray(f.values).view(np.uint8).ravel()

    # tree and grid headers
    # NanoVDB gives an empty level the offset of the level above it.
    a_upper = upper if n_upper else root
    a_lower = lower if n_lower else a_upper
    a_leaf = leaf if n_leaf else a_lower
    w.put(GRID_SIZE, "<i8", np.array([a_leaf, a_lower, a_upper, root]) - GRID_SIZE)
    w.put(GRID_SIZE + 32, "<u4", [n_leaf, n_lower, n_upper, 0, 0, 0])
    w.put(GRID_SIZE + 56, "<u8", int(counts.sum()))
    version = make_version(*WRITE_VERSION)
    flags = GridFlags.HAS_BBOX | GridFlags.IS_BREADTH_FIRST
    w.put(0, "<u8", [MAGIC_NUMB, 0])
    w.put(16, "<u4", [version, int(flags), 0, 1])
    w.put(32, "<u8", size)
    w.buf[GRID_OFF_GRID_NAME : GRID_OFF_GRID_NAME + len(raw_name)] = np.frombuffer(
        raw_name, np.uint8
    )
    m = GRID_OFF_MAP
    for dtype, base in (("<f4", m), ("<f8", m + 88)):  # mat, inverse, translation, taper
        w.put(base, dtype, np.concatenate([mat.ravel(), inv.ravel(), vec, [1.0]]))
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)])
    if n_upper:
        box = np.where(corners, bbox_hi + 1, bbox_lo) @ mat.T + vec
        w.put(560, "<f8", np.concatenate([box.min(axis=0), box.max(axis=0)]))
    else:
        w.put(560, "<f8", [np.finfo(np.float64).max] * 3 + [-np.finfo(np.float64).max] * 3)
    w.put(608, "<f8", mat.sum(axis=1))
    if grid_class is None:
        grid_class = GridClass.INDEX_GRID if lay.is_index else GridClass.UNKNOWN
    w.put(632, "<u4", [int(grid_class), int(grid_type)])
    w.put(640, "<i8", blind if features else size)
    w.put(648, "<u4", [len(features), 0])
    w.put(656, "<u8", [int(indexed.sum()) + 1 if lay.is_index else 0, MAGIC_GRID])
    sum64 = grid_checksum(w.buf.data, version) if checksum else CHECKSUM_DISABLED
    w.put(GRID_OFF_CHECKSUM, "<u8", sum64)
    return w.buf.tobytes()
