"""``GridInfo``: one NanoVDB grid, its bytes and the header fields a sampler needs.

``read_grids`` (``kdsl.geometry.nanovdb.reader``) returns one per grid of a file or
buffer, after checking every offset and count it lists against the grid's size; the
builder makes one for each grid it writes. All offsets are in bytes from the start of
``data`` (the grid's ``GridData``), so ``data[info.root_offset:]`` is the root node.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kdsl.geometry.nanovdb.layout import GridClass, GridType, ValueLayout


@dataclass(frozen=True)
class FeatureInfo:
    """One blind data array of a grid (a "feature array" in Warp's terms)."""

    name: str
    #: Byte offset of the first value from the start of the grid.
    offset: int
    value_count: int
    value_size: int
    #: A ``GridType`` number, as NanoVDB stores it.
    data_type: int
    #: The value type's name as Warp gives it ("float", "Vec3f", ...).
    type_str: str
    semantic: int
    data_class: int


@dataclass(frozen=True, eq=False)
class GridInfo:
    """One validated NanoVDB grid (its arrays are read-only)."""

    #: The grid's bytes, ``grid_size`` long, starting with its ``GridData``.
    data: bytes
    grid_type: GridType
    grid_class: GridClass
    #: Offsets and sizes for this value type (``layout.value_dtype`` is the value dtype,
    #: ``None`` for index grids).
    layout: ValueLayout
    name: str
    grid_index: int
    grid_count: int
    #: The packed NanoVDB version the grid was written with.
    version: int
    #: World size of a voxel along each axis (float64).
    voxel_size: tuple[float, float, float]
    #: 3x3 float64: ``world = index_to_world @ index + translation``.
    index_to_world: np.ndarray
    #: 3x3 float64, the inverse of ``index_to_world``.
    world_to_index: np.ndarray
    #: float64 (3,).
    translation: np.ndarray
    tree_offset: int
    root_offset: int
    #: Offsets of the first upper, lower and leaf node (736, the end of the tree header,
    #: for a level with no node).
    upper_offset: int
    lower_offset: int
    leaf_offset: int
    upper_count: int
    lower_count: int
    leaf_count: int
    #: Tiles in the root's table (children and values).
    root_tile_count: int
    #: Active tiles at the lower, upper and root levels (``TreeData.mTileCount``).
    tile_counts: tuple[int, int, int]
    #: Inclusive index bounding box of the active values: ((i, j, k), (i, j, k)).
    index_bbox: tuple[tuple[int, int, int], tuple[int, int, int]]
    #: World bounding box: ((x, y, z), (x, y, z)).
    world_bbox: tuple[tuple[float, float, float], tuple[float, float, float]]
    active_voxel_count: int
    #: The root's background value (a NumPy scalar or vector; an int for index grids).
    background: object
    #: For index grids, the number of values indexed (``GridData.mData1``); else 0.
    index_count: int
    blind_metadata_offset: int
    blind_metadata_count: int
    checksum: int
    #: The grid's blind data (feature arrays), in order.
    features: tuple[FeatureInfo, ...] = ()

    @property
    def grid_size(self) -> int:
        """The grid's size in bytes."""
        return len(self.data)

    @property
    def type_str(self) -> str:
        """The value type as NanoVDB and Warp name it ("float", "Vec3f", "OnIndex")."""
        return self.layout.type_str

    @property
    def is_index(self) -> bool:
        """Whether this is an index grid (values in a feature array, not the tree)."""
        return self.layout.is_index
