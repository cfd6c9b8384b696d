"""The records kernels read a ``kdsl.Volume`` through (``kdsl.stdlib.volume``).

``make_volume_record(owner, words, info, device)`` writes two records on ``device``
for a validated grid (``info``, a ``kdsl.geometry.nanovdb.GridInfo``) whose bytes are
``words`` (a 1-d ``uint32`` kdsl array on ``device``, the grid's buffer):

- the ``VolumeRecord`` at the returned record's id (``Volume.id``): the words and the
  word offsets and transforms every builtin reads, computed here once;
- a typed record (``VolumeFloat32``, ``VolumeVec3f``... or ``VolumeOther``), whose id
  the ``VolumeRecord`` holds, through which typed builtins read values, so that a
  debug build reports a value-type mismatch (``kd.check_record``).

Both live as long as ``owner``. Call it again after ``words`` is reallocated.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from kdsl.errors import KdslError
from kdsl.geometry.nanovdb.grid_info import GridInfo
from kdsl.geometry.nanovdb.layout import (
    GRID_OFF_MAP,
    LEAF_TABLE_COUNT,
    MAP_OFF_INVMATF,
    MAP_OFF_MATF,
    MAP_OFF_VECF,
    GridType,
)
from kdsl.runtime.array import array
from kdsl.runtime.objects import ObjectRecord
from kdsl.stdlib.volume import (
    INDEX_ACTIVE,
    INDEX_DENSE,
    INDEX_LEAF_OFFSET,
    VALUE_RECORDS,
    VolumeOther,
    VolumeRecord,
)

#: Word offsets are int32 in kernels: grids up to 8 GiB.
MAX_WORDS = 2**31 - 1
#: Warp's cap on ``volume_voxel_count``.
MAX_INDEXABLE_VOXELS = 2**31 - 1

_INDEX_KINDS = {
    GridType.INDEX: INDEX_LEAF_OFFSET, GridType.INDEXMASK: INDEX_LEAF_OFFSET,
    GridType.ONINDEX: INDEX_ACTIVE, GridType.ONINDEXMASK: INDEX_ACTIVE,
}  # fmt: skip


class VolumeRecordError(KdslError, ValueError):
    """A grid kernels cannot address (too large, or a layout off the 4-byte grid)."""


def _words(byte_offset: int, what: str) -> int:
    if byte_offset % 4:
        raise VolumeRecordError(f"the grid's {what} ({byte_offset} bytes) is not word aligned")
    return byte_offset // 4


def _map_f32(data: bytes, offset: int, count: int) -> np.ndarray:
    return np.frombuffer(data, dtype="<f4", count=count, offset=GRID_OFF_MAP + offset)


def voxel_count(info: GridInfo) -> int:
    """Warp's ``volume_voxel_count``: the active voxels of an OnIndex grid, else every
    leaf voxel, capped at ``2**31 - 1``."""
    if info.grid_type in (GridType.ONINDEX, GridType.ONINDEXMASK):
        count = info.active_voxel_count
    else:
        count = info.leaf_count * LEAF_TABLE_COUNT
    return min(count, MAX_INDEXABLE_VOXELS)


def volume_fields(info: GridInfo) -> dict[str, Any]:
    """The ``VolumeRecord`` fields of grid ``info`` (all but ``tag``, ``words``, ``typed``)."""
    lay = info.layout
    if info.grid_size // 4 > MAX_WORDS:
        raise VolumeRecordError(f"grid '{info.name}' has {info.grid_size} bytes; kernels "
                                f"address at most {4 * MAX_WORDS}")  # fmt: skip
    root = info.root_offset
    return {
        "grid_type": int(info.grid_type),
        "root": _words(root, "root"),
        "first_tile": _words(root + lay.root_size, "first root tile"),
        "tile_words": _words(lay.root_tile_size, "root tile size"),
        "tile_value": _words(lay.root_tile_off_value, "root tile value"),
        "tile_count": info.root_tile_count,
        "background": _words(root + lay.root_off_background, "background"),
        "upper_table": _words(lay.upper_off_table, "upper table"),
        "lower_table": _words(lay.lower_off_table, "lower table"),
        "table_words": _words(lay.table_stride, "table stride"),
        "leaf_table": _words(lay.leaf_off_table, "leaf table"),
        "value_words": 0 if lay.is_index else _words(lay.value_size, "value size"),
        "first_leaf": _words(info.leaf_offset, "first leaf"),
        "leaf_words": _words(lay.leaf_size, "leaf size"),
        "index_kind": _INDEX_KINDS.get(info.grid_type, INDEX_DENSE),
        "voxel_count": voxel_count(info),
        "matf": _map_f32(info.data, MAP_OFF_MATF, 9).reshape(3, 3),
        "invmatf": _map_f32(info.data, MAP_OFF_INVMATF, 9).reshape(3, 3),
        "vecf": _map_f32(info.data, MAP_OFF_VECF, 3),
        "matd": info.index_to_world,
        "invmatd": info.world_to_index,
        "vecd": info.translation,
    }


def make_volume_record(owner: Any, words: array, info: GridInfo, device: Any) -> ObjectRecord:
    """The ``VolumeRecord`` of grid ``info`` held in ``words`` on ``device`` (its ``id`` is
    the volume's id for kernels), and its typed record (kept as ``.typed_record``); both
    are freed with ``owner``."""
    fields = volume_fields(info)
    struct = VALUE_RECORDS.get(int(info.grid_type), VolumeOther)
    typed = ObjectRecord(owner, struct.__kdsl_type__, "volume", device)
    typed.write({"words": words})
    record = ObjectRecord(owner, VolumeRecord.__kdsl_type__, "volume", device)
    record.write({"words": words, "typed": typed.id, **fields})
    record.typed_record = typed  # type: ignore[attr-defined]
    return record
