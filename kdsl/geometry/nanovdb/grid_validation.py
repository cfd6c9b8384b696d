"""``parse_grid``: check one NanoVDB grid's bytes and describe them as a ``GridInfo``.

What is checked, in this order, so that no later read can leave the buffer: the header
(magic, major version, size, grid type and class, breadth-first layout, name, a finite
transform), the blind metadata table and the ranges of its data, the node arrays (each
level's offset aligned, inside the grid, after the previous level and before the blind
data, its count bounded by the bytes left), the root's tile count, every child reference
of the root and internal nodes (it must land exactly on a node of the next level, as in
Warp's validator), for index grids every index a leaf gives (below the grid's
value count), and the checksum (unless disabled). Node contents beyond that (keys,
bounding boxes, statistics) are data, not structure: wrong ones give wrong samples,
never a bad read.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

import numpy as np

from kdsl.geometry.nanovdb.checksum import checksum_matches, grid_checksum
from kdsl.geometry.nanovdb.errors import NanoVDBError
from kdsl.geometry.nanovdb.grid_info import FeatureInfo, GridInfo
from kdsl.geometry.nanovdb.layout import (
    BLIND_METADATA_SIZE,
    DATA_ALIGNMENT,
    GRID_MAGICS,
    GRID_NAME_SIZE,
    GRID_OFF_GRID_NAME,
    GRID_OFF_MAP,
    GRID_SIZE,
    LEAF_OFF_INDEX_OFFSET,
    LEAF_OFF_VALUE_MASK,
    LOWER_OFF_CHILD_MASK,
    LOWER_TABLE_COUNT,
    MAJOR_VERSION,
    MAP_OFF_INVMATD,
    MAP_OFF_MATD,
    MAP_OFF_VECD,
    ROOT_BASE_SIZE,
    ROOT_OFF_BBOX_MIN,
    TREE_SIZE,
    UPPER_OFF_CHILD_MASK,
    UPPER_TABLE_COUNT,
    GridClass,
    GridFlags,
    GridType,
    ValueLayout,
    grid_type_name,
    value_layout,
    version_major,
    version_string,
)

_GRID_HEADER = struct.Struct("<QQIIIIQ")  # magic .. grid size (bytes 0..40)
_GRID_TAIL = struct.Struct("<6d3dIIqIIQQ")  # world bbox .. data2 (bytes 560..672)
_TREE = struct.Struct("<4q3I3IQ")
_BLIND = np.dtype(
    {
        "names": [
            "data_offset",
            "value_count",
            "value_size",
            "semantic",
            "data_class",
            "data_type",
        ],
        "formats": ["<i8", "<u8", "<u4", "<u4", "<u4", "<u4"],
        "offsets": [0, 8, 16, 20, 24, 28],
        "itemsize": BLIND_METADATA_SIZE,
    }
)


@dataclass(frozen=True)
class _Level:
    """One level's node array: absolute offset, count, node size."""

    begin: int
    count: int
    size: int

    @property
    def end(self) -> int:
        return self.begin + self.count * self.size

    def starts(self, offsets: np.ndarray) -> np.ndarray:
        """Whether each absolute offset is the start of one of these nodes."""
        rel = offsets - self.begin
        return (rel >= 0) & (rel < self.count * self.size) & (rel % self.size == 0)


class _Grid:
    """The bytes of one grid and where errors about it come from."""

    def __init__(self, data: bytes, source: str, index: int) -> None:
        self.data, self.size = data, len(data)
        self.u8 = np.frombuffer(data, dtype=np.uint8)
        self.source, self.what = source, f"grid {index}"

    def error(self, message: str) -> NanoVDBError:
        return NanoVDBError(f"{self.source}: {self.what}: {message}")

    def array(self, offset: int, dtype: str, count: int) -> np.ndarray:
        return np.frombuffer(self.data, dtype=dtype, count=count, offset=offset)

    def node_bytes(self, level: _Level) -> np.ndarray:
        return self.u8[level.begin : level.end].reshape(level.count, level.size)

    def level(self, tree_rel: int, count: int, size: int, name: str) -> _Level:
        if count == 0:
            return _Level(GRID_SIZE + TREE_SIZE, 0, size)
        begin = GRID_SIZE + tree_rel
        if tree_rel < TREE_SIZE or tree_rel % DATA_ALIGNMENT or begin > self.size:
            raise self.error(f"corrupt: the {name} node offset {tree_rel} is outside the grid "
                             f"or misaligned")  # fmt: skip
        if count > (self.size - begin) // size:
            raise self.error(f"truncated or corrupt: {count} {name} nodes of {size} bytes at "
                             f"byte {begin} overrun the grid's {self.size} bytes")  # fmt: skip
        return _Level(begin, count, size)


def _header(g: _Grid) -> tuple:
    magic, checksum, version, flags, index, count, size = _GRID_HEADER.unpack_from(g.data, 0)
    if magic not in GRID_MAGICS:
        raise g.error(f"not a NanoVDB grid: wrong magic number 0x{magic:016x}")
    if version_major(version) != MAJOR_VERSION:
        raise g.error(f"unsupported NanoVDB version {version_string(version)}: kdsl reads "
                      f"major version {MAJOR_VERSION}")  # fmt: skip
    if size != g.size or size % DATA_ALIGNMENT:
        raise g.error(f"corrupt: its size field says {size} bytes, it has {g.size}")
    if not index < count:
        raise g.error(f"corrupt: grid index {index} of a count of {count}")
    return checksum, version, flags, index, count


def _name(g: _Grid) -> str:
    raw = g.data[GRID_OFF_GRID_NAME : GRID_OFF_GRID_NAME + GRID_NAME_SIZE]
    end = raw.find(b"\0")
    if end < 0:
        raise g.error("corrupt: its name is not NUL-terminated")
    return raw[:end].decode("utf-8", "replace")


def _transform(g: _Grid) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    mat = g.array(GRID_OFF_MAP + MAP_OFF_MATD, "<f8", 9).reshape(3, 3)
    inv = g.array(GRID_OFF_MAP + MAP_OFF_INVMATD, "<f8", 9).reshape(3, 3)
    vec = g.array(GRID_OFF_MAP + MAP_OFF_VECD, "<f8", 3)
    single = g.array(GRID_OFF_MAP, "<f4", 21)  # the float32 copy kernels use
    if not all(np.isfinite(a).all() for a in (mat, inv, vec, single)):
        raise g.error("corrupt: its index-to-world transform is not finite")
    return mat, inv, vec


def _features(g: _Grid, offset: int, count: int) -> tuple[FeatureInfo, ...]:
    if offset < 0 or offset > g.size or count > (g.size - offset) // BLIND_METADATA_SIZE:
        raise g.error(f"corrupt: {count} blind data records at byte {offset} do not fit")
    metas = g.array(offset, _BLIND, count) if count else []
    out = []
    for i, meta in enumerate(metas):
        at = offset + i * BLIND_METADATA_SIZE
        data_at = at + int(meta["data_offset"])
        n, size = int(meta["value_count"]), int(meta["value_size"])
        if not 0 <= data_at <= g.size or (size and n > (g.size - data_at) // size):
            raise g.error(f"corrupt: blind data {i} ({n} values of {size} bytes) lies outside "
                          f"the grid")  # fmt: skip
        raw_name = g.data[at + 32 : at + 32 + GRID_NAME_SIZE]
        if b"\0" not in raw_name:
            raise g.error(f"corrupt: the name of blind data {i} is not NUL-terminated")
        name = raw_name.split(b"\0")[0].decode("utf-8", "replace")
        dtype = int(meta["data_type"])
        layout = value_layout(dtype)
        type_str = layout.type_str if layout is not None else grid_type_name(dtype).lower()
        out.append(FeatureInfo(name, data_at, n, size, dtype, type_str, int(meta["semantic"]),
                               int(meta["data_class"])))  # fmt: skip
    return tuple(out)


def _check_children(g: _Grid, parent: _Level, mask_off: int, table_off: int, slots: int,
                    stride: int, child: _Level, name: str) -> None:  # fmt: skip
    """Every child a node's child mask lists must start a node of ``child``'s level."""
    if parent.count == 0:
        return
    nodes = g.node_bytes(parent)
    bits = np.unpackbits(nodes[:, mask_off : mask_off + slots // 8], axis=1, bitorder="little")
    node, slot = np.nonzero(bits)
    cols = table_off + slot[:, None] * stride + np.arange(8)
    rel = np.ascontiguousarray(nodes[node[:, None], cols]).view("<i8")[:, 0]
    if not child.starts(parent.begin + node.astype(np.int64) * parent.size + rel).all():
        raise g.error(f"corrupt: a {name} node's child offset does not point at a node")


def _check_indices(g: _Grid, lay: ValueLayout, leaves: _Level, index_count: int) -> None:
    """Index grids: each leaf's indices (its first, plus its active count or 512) must
    be below the grid's value count, and an OnIndex leaf's prefix sums must be right."""
    if leaves.count == 0:
        return
    nodes = g.node_bytes(leaves)
    first = np.ascontiguousarray(nodes[:, LEAF_OFF_INDEX_OFFSET : LEAF_OFF_INDEX_OFFSET + 16])
    offset, prefix = first.view("<u8")[:, 0], first.view("<u8")[:, 1]
    words = np.ascontiguousarray(nodes[:, LEAF_OFF_VALUE_MASK : LEAF_OFF_VALUE_MASK + 64])
    counts = np.unpackbits(words, axis=1).reshape(-1, 8, 64).sum(axis=2)
    if lay.grid_type == GridType.ONINDEX:
        sums = np.cumsum(counts, axis=1)[:, :7].astype(np.uint64)
        expect = np.bitwise_or.reduce(sums << (np.arange(7, dtype=np.uint64) * 9), axis=1)
        if not (prefix == expect).all():
            raise g.error("corrupt: an OnIndex leaf's prefix sums disagree with its mask")
        used = counts.sum(axis=1).astype(np.uint64)
    else:
        used = np.full(leaves.count, 512, dtype=np.uint64)
    total = np.uint64(index_count)
    if ((used > total) | (offset > total - np.minimum(used, total))).any():
        raise g.error(f"corrupt: a leaf indexes values beyond the grid's {index_count}")


def parse_grid(data: bytes, source: str, index: int, verify_checksum: bool = True) -> GridInfo:
    """Validate one grid's bytes (exactly its size) and return its ``GridInfo``; raise
    ``NanoVDBError`` naming ``source``, the grid and the fault. ``verify_checksum=False``
    skips the checksum (for live in-memory buffers whose values kernels may have changed)."""
    g = _Grid(data, source, index)
    if g.size < GRID_SIZE + TREE_SIZE:
        raise g.error(f"truncated: {g.size} bytes cannot hold a grid")
    checksum, version, flags, grid_index, grid_count = _header(g)
    name = _name(g)
    if name:
        g.what = f"grid {index} ({name!r})"
    (*wbbox, vx, vy, vz, grid_class, grid_type, blind_off, blind_count, _d0, index_count,
     _d2) = _GRID_TAIL.unpack_from(data, 560)  # fmt: skip
    lay = value_layout(grid_type)
    if lay is None:
        raise g.error(f"unsupported grid type {grid_type_name(grid_type)}: kdsl reads "
                      f"float, double, int, uint, vec3/vec4, index and OnIndex grids")  # fmt: skip
    if grid_class >= len(GridClass):
        raise g.error(f"corrupt: unknown grid class {grid_class}")
    if not flags & GridFlags.IS_BREADTH_FIRST:
        raise g.error("unsupported layout: the grid is not stored breadth-first")
    mat, inv, vec = _transform(g)
    features = _features(g, blind_off, blind_count)
    rel_leaf, rel_lower, rel_upper, rel_root, n_leaf, n_lower, n_upper, *tiles, voxels = (
        _TREE.unpack_from(data, GRID_SIZE)
    )
    root = g.level(rel_root, 1, lay.root_size, "root")
    (tile_count,) = struct.unpack_from("<I", data, root.begin + ROOT_BASE_SIZE - 4)
    if tile_count > (g.size - root.end) // lay.root_tile_size:
        raise g.error(f"truncated or corrupt: {tile_count} root tiles overrun the grid")
    upper = g.level(rel_upper, n_upper, lay.upper_size, "upper")
    lower = g.level(rel_lower, n_lower, lay.lower_size, "lower")
    leaf = g.level(rel_leaf, n_leaf, lay.leaf_size, "leaf")
    end = root.end + tile_count * lay.root_tile_size
    for level in (upper, lower, leaf):
        if level.count:
            if level.begin < end:
                raise g.error("corrupt: the node arrays overlap or are out of order")
            end = level.end
    if end > (blind_off if blind_count or blind_off else g.size):
        raise g.error("corrupt: the tree overlaps the blind data")
    tile_child = g.array(root.end, "<i8", tile_count * lay.root_tile_size // 8)
    tile_child = tile_child.reshape(tile_count, lay.root_tile_size // 8)[:, 1]
    if not upper.starts(root.begin + tile_child[tile_child != 0]).all():
        raise g.error("corrupt: a root tile's child offset does not point at an upper node")
    _check_children(g, upper, UPPER_OFF_CHILD_MASK, lay.upper_off_table, UPPER_TABLE_COUNT,
                    lay.table_stride, lower, "upper")  # fmt: skip
    _check_children(g, lower, LOWER_OFF_CHILD_MASK, lay.lower_off_table, LOWER_TABLE_COUNT,
                    lay.table_stride, leaf, "lower")  # fmt: skip
    if lay.is_index:
        _check_indices(g, lay, leaf, index_count)
    spans = tuple((lv.begin, lv.count, lv.size) for lv in (upper, lower, leaf))
    if verify_checksum and not checksum_matches(checksum, grid_checksum(data, version, spans)):
        raise g.error(f"bad checksum 0x{checksum:016x}: the grid's bytes were changed after "
                      f"it was written")  # fmt: skip
    bbox = struct.unpack_from("<6i", data, root.begin + ROOT_OFF_BBOX_MIN)
    if lay.is_index:
        background: object = int(g.array(root.begin + lay.root_off_background, "<u8", 1)[0])
    else:
        count = math.prod(lay.value_shape)
        value = g.array(root.begin + lay.root_off_background, lay.value_dtype, count)
        background = value[0] if not lay.value_shape else value.copy()
    for a in (mat, inv, vec):
        a.flags.writeable = False
    return GridInfo(
        data=data, grid_type=GridType(grid_type), grid_class=GridClass(grid_class), layout=lay,
        name=name, grid_index=grid_index, grid_count=grid_count, version=version,
        voxel_size=(vx, vy, vz), index_to_world=mat, world_to_index=inv, translation=vec,
        tree_offset=GRID_SIZE, root_offset=root.begin,
        upper_offset=upper.begin, lower_offset=lower.begin, leaf_offset=leaf.begin, upper_count=n_upper, lower_count=n_lower, leaf_count=n_leaf,
        root_tile_count=tile_count, tile_counts=tuple(tiles),
        index_bbox=(tuple(bbox[:3]), tuple(bbox[3:])),
        world_bbox=(tuple(wbbox[:3]), tuple(wbbox[3:])), active_voxel_count=voxels,
        background=background, index_count=index_count if lay.is_index else 0,
        blind_metadata_offset=blind_off, blind_metadata_count=blind_count,
        checksum=checksum, features=features,
    )  # fmt: skip
