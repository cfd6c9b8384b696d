"""The byte layout of NanoVDB grids and files (NanoVDB ABI version 32), as constants.

A NanoVDB grid is one contiguous, little-endian buffer, every part 32-byte aligned::

    [GridData 672][TreeData 64][RootData][root tiles...][upper nodes...][lower nodes...]
    [leaf nodes...][blind metadata...][blind data...]

Offsets named ``*_OFF_*`` are relative to the start of their own structure. Child
references are signed byte offsets: a root tile's from the root, an internal node's
table entry from that node. The tree is 4 levels: the root (a table of tiles keyed by
the origin of a 4096^3 region), upper internal nodes (32^3 children each, 4096^3
voxels), lower internal nodes (16^3 children, 128^3 voxels) and leaves (8^3 voxels).

Where a field's offset depends on the value type (the background, the min/max/average/
std-dev statistics, the tables), ``value_layout(grid_type)`` gives it: a ``ValueLayout``
computed from the value's size and alignment with NanoVDB's rules (fields in order,
each at its alignment, every structure padded to 32 bytes). The public PNanoVDB header
lists the same numbers; ``tests/geometry/test_volume_format.py`` checks a few.

A file is a sequence of segments: a ``FileHeader`` (16 bytes), one ``FileMetaData``
(176 bytes) plus the grid's name (``name_size`` bytes with its NUL) per grid, then the
grids' bytes, raw or, for ZIP and BLOSC, as chunks each preceded by its int64 size.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

#: "NanoVDB0": a grid (or file header) of ABI version 32.0 to 32.6.
MAGIC_NUMB = 0x304244566F6E614E
#: "NanoVDB1": a grid written since version 32.7.
MAGIC_GRID = 0x314244566F6E614E
#: "NanoVDB2": a file header written since version 32.7.
MAGIC_FILE = 0x324244566F6E614E
GRID_MAGICS = (MAGIC_NUMB, MAGIC_GRID)
FILE_MAGICS = (MAGIC_NUMB, MAGIC_FILE)

#: The ABI (major) version a reader must match; minor and patch may differ.
MAJOR_VERSION = 32
#: The version kdsl writes (that of the PNanoVDB header Warp 1.19 ships). Grids and files
#: carry the magic "NanoVDB0", which every reader of major version 32 accepts, with
#: ``MAGIC_GRID`` in ``GridData.mData2`` as NanoVDB itself writes them.
WRITE_VERSION = (32, 8, 0)


def make_version(major: int, minor: int, patch: int) -> int:
    """Pack a version as NanoVDB does: 11 bits major, 11 bits minor, 10 bits patch."""
    return (major << 21) | (minor << 10) | patch


def version_major(version: int) -> int:
    """The major (ABI) number of a packed version."""
    return (version >> 21) & 0x7FF


def version_string(version: int) -> str:
    """A packed version as "major.minor.patch"."""
    return f"{version_major(version)}.{(version >> 10) & 0x7FF}.{version & 0x3FF}"


class GridType(enum.IntEnum):
    """NanoVDB's ``GridType``: the type of a grid's values (its build type)."""

    UNKNOWN = 0
    FLOAT = 1
    DOUBLE = 2
    INT16 = 3
    INT32 = 4
    INT64 = 5
    VEC3F = 6
    VEC3D = 7
    MASK = 8
    HALF = 9
    UINT32 = 10
    BOOLEAN = 11
    RGBA8 = 12
    FP4 = 13
    FP8 = 14
    FP16 = 15
    FPN = 16
    VEC4F = 17
    VEC4D = 18
    INDEX = 19
    ONINDEX = 20
    INDEXMASK = 21
    ONINDEXMASK = 22
    POINTINDEX = 23
    VEC3U8 = 24
    VEC3U16 = 25
    UINT8 = 26


class GridClass(enum.IntEnum):
    """NanoVDB's ``GridClass``: what a grid's values mean."""

    UNKNOWN = 0
    LEVEL_SET = 1
    FOG_VOLUME = 2
    STAGGERED = 3
    POINT_INDEX = 4
    POINT_DATA = 5
    TOPOLOGY = 6
    VOXEL_VOLUME = 7
    INDEX_GRID = 8
    TENSOR_GRID = 9


class GridFlags(enum.IntFlag):
    """Bits of ``GridData.mFlags``."""

    HAS_LONG_GRID_NAME = 1 << 0
    HAS_BBOX = 1 << 1
    HAS_MIN_MAX = 1 << 2
    HAS_AVERAGE = 1 << 3
    HAS_STD_DEVIATION = 1 << 4
    IS_BREADTH_FIRST = 1 << 5


class Codec(enum.IntEnum):
    """NanoVDB's file compression codecs (``io::Codec``)."""

    NONE = 0
    ZIP = 1
    BLOSC = 2


#: Every NanoVDB structure starts at a multiple of this.
DATA_ALIGNMENT = 32

# --- file ---------------------------------------------------------------------------
FILE_HEADER_SIZE = 16
FILE_HEADER_OFF_MAGIC = 0  # uint64
FILE_HEADER_OFF_VERSION = 8  # uint32
FILE_HEADER_OFF_GRID_COUNT = 12  # uint16
FILE_HEADER_OFF_CODEC = 14  # uint16

FILE_METADATA_SIZE = 176
FILE_META_OFF_GRID_SIZE = 0  # uint64, bytes of the grid in memory
FILE_META_OFF_FILE_SIZE = 8  # uint64, bytes of the grid on disk
FILE_META_OFF_NAME_KEY = 16  # uint64
FILE_META_OFF_VOXEL_COUNT = 24  # uint64
FILE_META_OFF_GRID_TYPE = 32  # uint32
FILE_META_OFF_GRID_CLASS = 36  # uint32
FILE_META_OFF_WORLD_BBOX = 40  # 6 x float64
FILE_META_OFF_INDEX_BBOX = 88  # 6 x int32
FILE_META_OFF_VOXEL_SIZE = 112  # 3 x float64
FILE_META_OFF_NAME_SIZE = 136  # uint32, with the NUL
FILE_META_OFF_NODE_COUNT = 140  # 4 x uint32: leaf, lower, upper, root (1)
FILE_META_OFF_TILE_COUNT = 156  # 3 x uint32: lower, upper, root
FILE_META_OFF_CODEC = 168  # uint16
FILE_META_OFF_VERSION = 172  # uint32

# --- GridData -----------------------------------------------------------------------
GRID_SIZE = 672
GRID_OFF_MAGIC = 0  # uint64
GRID_OFF_CHECKSUM = 8  # uint64: CRC32 of the head (low word), of the nodes (high word)
GRID_OFF_VERSION = 16  # uint32
GRID_OFF_FLAGS = 20  # uint32
GRID_OFF_GRID_INDEX = 24  # uint32
GRID_OFF_GRID_COUNT = 28  # uint32
GRID_OFF_GRID_SIZE = 32  # uint64
GRID_OFF_GRID_NAME = 40  # 256 bytes, NUL terminated
GRID_NAME_SIZE = 256
GRID_OFF_MAP = 296  # Map (below)
GRID_OFF_WORLD_BBOX = 560  # 6 x float64
GRID_OFF_VOXEL_SIZE = 608  # 3 x float64
GRID_OFF_GRID_CLASS = 632  # uint32
GRID_OFF_GRID_TYPE = 636  # uint32
GRID_OFF_BLIND_METADATA_OFFSET = 640  # int64, from the grid
GRID_OFF_BLIND_METADATA_COUNT = 648  # uint32
GRID_OFF_DATA0 = 652  # uint32, unused
GRID_OFF_DATA1 = 656  # uint64, the number of values an index grid indexes
GRID_OFF_DATA2 = 664  # uint64, MAGIC_GRID in 32.6 grids
#: A checksum of all ones means "not computed".
CHECKSUM_DISABLED = 0xFFFFFFFFFFFFFFFF
CHECKSUM_HALF_DISABLED = 0xFFFFFFFF

# Map: index-to-world (mat, vec) and world-to-index (invmat), in float32 then float64.
MAP_SIZE = 264
MAP_OFF_MATF = 0  # 9 x float32, row-major: world = mat @ index + vec
MAP_OFF_INVMATF = 36  # 9 x float32
MAP_OFF_VECF = 72  # 3 x float32
MAP_OFF_TAPERF = 84  # float32 (1.0)
MAP_OFF_MATD = 88  # 9 x float64
MAP_OFF_INVMATD = 160  # 9 x float64
MAP_OFF_VECD = 232  # 3 x float64
MAP_OFF_TAPERD = 256  # float64 (1.0)

# --- GridBlindMetaData (feature arrays) -----------------------------------------------
BLIND_METADATA_SIZE = 288
BLIND_OFF_DATA_OFFSET = 0  # int64, from this metadata record
BLIND_OFF_VALUE_COUNT = 8  # uint64
BLIND_OFF_VALUE_SIZE = 16  # uint32
BLIND_OFF_SEMANTIC = 20  # uint32
BLIND_OFF_DATA_CLASS = 24  # uint32
BLIND_OFF_DATA_TYPE = 28  # uint32, a GridType
BLIND_OFF_NAME = 32  # 256 bytes

# --- TreeData (right after GridData) ------------------------------------------------
TREE_SIZE = 64
TREE_OFF_NODE_OFFSET_LEAF = 0  # int64 from the tree; 0 when there is no leaf
TREE_OFF_NODE_OFFSET_LOWER = 8  # int64
TREE_OFF_NODE_OFFSET_UPPER = 16  # int64
TREE_OFF_NODE_OFFSET_ROOT = 24  # int64
TREE_OFF_NODE_COUNT_LEAF = 32  # uint32
TREE_OFF_NODE_COUNT_LOWER = 36  # uint32
TREE_OFF_NODE_COUNT_UPPER = 40  # uint32
TREE_OFF_TILE_COUNT_LOWER = 44  # uint32: active tiles in lower nodes
TREE_OFF_TILE_COUNT_UPPER = 48  # uint32
TREE_OFF_TILE_COUNT_ROOT = 52  # uint32
TREE_OFF_VOXEL_COUNT = 56  # uint64: active voxels

# --- RootData and its tiles -----------------------------------------------------------
ROOT_OFF_BBOX_MIN = 0  # 3 x int32, index bbox of the active values
ROOT_OFF_BBOX_MAX = 12  # 3 x int32, inclusive
ROOT_OFF_TABLE_SIZE = 24  # uint32, number of tiles
ROOT_BASE_SIZE = 28
ROOT_TILE_OFF_KEY = 0  # uint64 (coord_to_key)
ROOT_TILE_OFF_CHILD = 8  # int64 from the root, 0 for a value tile
ROOT_TILE_OFF_STATE = 16  # uint32, a value tile's active state
ROOT_TILE_BASE_SIZE = 20

# --- internal and leaf nodes ----------------------------------------------------------
NODE_OFF_BBOX_MIN = 0  # 3 x int32 (every node)
NODE_OFF_BBOX_MAX = 12  # 3 x int32, internal nodes
NODE_OFF_FLAGS = 24  # uint64, internal nodes
NODE_OFF_VALUE_MASK = 32  # internal nodes
LEAF_OFF_BBOX_DIF_AND_FLAGS = 12  # 3 x uint8 bbox size - 1, 1 x uint8 flags
LEAF_OFF_VALUE_MASK = 16  # 64 bytes
LEAF_OFF_INDEX_OFFSET = 80  # uint64, index leaves: the first active value's index
LEAF_OFF_INDEX_PREFIX_SUM = 88  # uint64, index leaves: 7 x 9-bit running counts
LEAF_FLAG_HAS_BBOX = 1 << 1
LEAF_FLAG_HAS_STATS = 1 << 4

#: log2 of a node's side in children, per level (leaf, lower, upper).
LOG2_DIM = (3, 4, 5)
#: log2 of a node's side in voxels, per level (leaf, lower, upper): 8, 128, 4096.
TOTAL_LOG2_DIM = (3, 7, 12)
UPPER_TABLE_COUNT = 1 << 15  # 32^3
LOWER_TABLE_COUNT = 1 << 12  # 16^3
LEAF_TABLE_COUNT = 1 << 9  # 8^3
UPPER_OFF_CHILD_MASK = NODE_OFF_VALUE_MASK + UPPER_TABLE_COUNT // 8  # 4128
LOWER_OFF_CHILD_MASK = NODE_OFF_VALUE_MASK + LOWER_TABLE_COUNT // 8  # 544
UPPER_BASE_SIZE = UPPER_OFF_CHILD_MASK + UPPER_TABLE_COUNT // 8  # 8224
LOWER_BASE_SIZE = LOWER_OFF_CHILD_MASK + LOWER_TABLE_COUNT // 8  # 1056
LEAF_BASE_SIZE = LEAF_OFF_VALUE_MASK + LEAF_TABLE_COUNT // 8  # 80


def coord_to_key(i: int, j: int, k: int) -> int:
    """The root key of the 4096^3 region holding voxel ``(i, j, k)``: 21 bits per axis,
    x highest (NanoVDB's single 64-bit root key)."""
    mask = (1 << 21) - 1
    return (
        (((i & 0xFFFFFFFF) >> 12) & mask) << 42
        | (((j & 0xFFFFFFFF) >> 12) & mask) << 21
        | ((k & 0xFFFFFFFF) >> 12) & mask
    )


def _align(offset: int, alignment: int) -> int:
    return -(-offset // alignment) * alignment


@dataclass(frozen=True)
class ValueLayout:
    """Offsets and sizes that depend on a grid's value type (PNanoVDB's
    ``grid_type_constants``), in bytes from the start of each structure.

    ``value_dtype`` is the NumPy dtype of one value (``None`` for index grids, whose
    leaves hold no values), ``value_shape`` its vector length (``()`` for scalars).
    For index grids the tile "values" are uint64 indices and leaves have no table
    (``leaf_off_table`` = ``leaf_size`` - 16: the offset and prefix-sum words)."""

    grid_type: GridType
    type_str: str
    value_dtype: np.dtype | None
    value_shape: tuple[int, ...]
    value_size: int
    root_off_background: int
    root_off_min: int
    root_off_max: int
    root_off_ave: int
    root_off_stddev: int
    root_size: int
    root_tile_off_value: int
    root_tile_size: int
    table_stride: int
    upper_off_min: int
    upper_off_max: int
    upper_off_ave: int
    upper_off_stddev: int
    upper_off_table: int
    upper_size: int
    lower_off_min: int
    lower_off_max: int
    lower_off_ave: int
    lower_off_stddev: int
    lower_off_table: int
    lower_size: int
    leaf_off_min: int
    leaf_off_max: int
    leaf_off_ave: int
    leaf_off_stddev: int
    leaf_off_table: int
    leaf_size: int

    @property
    def is_index(self) -> bool:
        """Whether the grid is an index grid (its values live outside the tree)."""
        return self.value_dtype is None

    def node_size(self, level: int) -> int:
        """The byte size of a node of ``level`` (0 leaf, 1 lower, 2 upper)."""
        return (self.leaf_size, self.lower_size, self.upper_size)[level]


def _stats(start: int, value: tuple[int, int], stat: tuple[int, int]) -> tuple[int, ...]:
    """Offsets of min, max, average, std-dev laid out from ``start``, and their end."""
    vmin = _align(start, value[1])
    vmax = vmin + value[0]
    ave = _align(vmax + value[0], stat[1])
    std = ave + stat[0]
    return vmin, vmax, ave, std, std + stat[0]


def _make_layout(grid_type, type_str, dtype, shape, value, stat) -> ValueLayout:
    size, align = value
    bg = _align(ROOT_BASE_SIZE, align)
    r_min, r_max, r_ave, r_std, r_end = _stats(bg + size, value, stat)
    tile_value = _align(ROOT_TILE_BASE_SIZE, align)
    # An internal node's table entry is a union of a value and an int64 child offset.
    stride = _align(max(size, 8), max(align, 8))
    u = _stats(UPPER_BASE_SIZE, value, stat)
    lo = _stats(LOWER_BASE_SIZE, value, stat)
    u_table, lo_table = _align(u[4], DATA_ALIGNMENT), _align(lo[4], DATA_ALIGNMENT)
    if dtype is None:  # index leaves: two uint64 words, no statistics, no values
        leaf = (LEAF_BASE_SIZE,) * 5
        leaf_size = _align(LEAF_BASE_SIZE + 16, DATA_ALIGNMENT)
    else:
        leaf = _stats(LEAF_BASE_SIZE, value, stat)
        leaf = (*leaf[:4], _align(leaf[4], DATA_ALIGNMENT))
        leaf_size = _align(leaf[4] + LEAF_TABLE_COUNT * size, DATA_ALIGNMENT)
    return ValueLayout(
        grid_type, type_str, None if dtype is None else np.dtype(dtype), shape, size,
        bg, r_min, r_max, r_ave, r_std, _align(r_end, DATA_ALIGNMENT),
        tile_value, _align(tile_value + size, DATA_ALIGNMENT), stride,
        *u[:4], u_table, _align(u_table + UPPER_TABLE_COUNT * stride, DATA_ALIGNMENT),
        *lo[:4], lo_table, _align(lo_table + LOWER_TABLE_COUNT * stride, DATA_ALIGNMENT),
        *leaf, leaf_size,
    )  # fmt: skip


_F32, _F64, _U64 = (4, 4), (8, 8), (8, 8)
# grid type: (type_str as Warp names it, value dtype, value shape, (size, align), stats)
_VALUE_TYPES = {
    GridType.FLOAT: ("float", "<f4", (), (4, 4), _F32),
    GridType.DOUBLE: ("double", "<f8", (), (8, 8), _F64),
    GridType.INT16: ("int16", "<i2", (), (2, 2), _F32),
    GridType.INT32: ("int32", "<i4", (), (4, 4), _F32),
    GridType.INT64: ("int64", "<i8", (), (8, 8), _F64),
    GridType.VEC3F: ("Vec3f", "<f4", (3,), (12, 4), _F32),
    GridType.VEC3D: ("Vec3d", "<f8", (3,), (24, 8), _F64),
    GridType.HALF: ("Half", "<f2", (), (2, 2), _F32),
    GridType.UINT32: ("uint32", "<u4", (), (4, 4), _F32),
    GridType.VEC4F: ("Vec4f", "<f4", (4,), (16, 4), _F32),
    GridType.VEC4D: ("Vec4d", "<f8", (4,), (32, 8), _F64),
    GridType.VEC3U8: ("Vec3u8", "u1", (3,), (3, 1), _F32),
    GridType.VEC3U16: ("Vec3u16", "<u2", (3,), (6, 2), _F32),
    GridType.UINT8: ("uint8", "u1", (), (1, 1), _F32),
    GridType.INDEX: ("Index", None, (), (8, 8), _U64),
    GridType.ONINDEX: ("OnIndex", None, (), (8, 8), _U64),
}

#: The value layouts of every grid type kdsl reads and writes.
VALUE_LAYOUTS: dict[GridType, ValueLayout] = {
    gt: _make_layout(gt, *spec) for gt, spec in _VALUE_TYPES.items()
}


def value_layout(grid_type: int) -> ValueLayout | None:
    """The ``ValueLayout`` of ``grid_type``, or ``None`` for a type kdsl does not read
    (masks, booleans, quantized Fp4/8/16/N, point grids, RGBA8)."""
    try:
        return VALUE_LAYOUTS.get(GridType(grid_type))
    except ValueError:
        return None


def grid_type_name(grid_type: int) -> str:
    """A grid type's name for messages (``FLOAT``, ``ONINDEX``, or the number)."""
    try:
        return GridType(grid_type).name
    except ValueError:
        return f"unknown ({grid_type})"
