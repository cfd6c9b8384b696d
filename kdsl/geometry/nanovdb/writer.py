"""``write_nvdb``: NanoVDB file bytes for grids, as NanoVDB's ``io::writeGrids`` lays them
out: one segment (a ``FileHeader``, then each grid's ``FileMetaData`` and name, then
the grids, stored under the segment's codec). ``fileSize`` counts a grid's stored bytes
with its chunk sizes, which NanoVDB's reader uses to skip grids, and ``nameKey`` is
NanoVDB's hash of the name, which its name lookups compare.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

from kdsl.geometry.nanovdb.codecs import compress_grid
from kdsl.geometry.nanovdb.grid_info import GridInfo
from kdsl.geometry.nanovdb.layout import (
    FILE_METADATA_SIZE,
    MAGIC_NUMB,
    WRITE_VERSION,
    Codec,
    make_version,
)

_HEADER = struct.Struct("<QIHH")
_META = struct.Struct("<QQQQII6d6i3dI4I3IHHI")
assert _META.size == FILE_METADATA_SIZE


def name_key(name: str) -> int:
    """NanoVDB's ``io::stringHash`` of a grid name (0 for the empty name)."""
    key = 0
    for byte in name.encode("utf-8"):
        key = (key * 67 + byte + (key >> 56)) & 0xFFFFFFFFFFFFFFFF
    return key


def _metadata(info: GridInfo, stored: int, codec: Codec, version: int) -> bytes:
    name = info.name.encode("utf-8") + b"\0"
    (i0, j0, k0), (i1, j1, k1) = info.index_bbox
    return _META.pack(
        info.grid_size, stored, name_key(info.name), info.active_voxel_count,
        int(info.grid_type), int(info.grid_class), *info.world_bbox[0], *info.world_bbox[1],
        i0, j0, k0, i1, j1, k1, *info.voxel_size, len(name),
        info.leaf_count, info.lower_count, info.upper_count, 1, *info.tile_counts,
        int(codec), 0, version,
    ) + name  # fmt: skip


def write_nvdb(grids: Sequence[GridInfo], codec: Codec = Codec.NONE, source: str = "") -> bytes:
    """The bytes of a ``.nvdb`` file holding ``grids`` (at most 65535) under ``codec``."""
    version = make_version(*WRITE_VERSION)
    stored = [compress_grid(g.data, codec, source or "save_to_nvdb") for g in grids]
    parts = [_HEADER.pack(MAGIC_NUMB, version, len(grids), int(codec))]
    parts += [_metadata(g, len(s), codec, version) for g, s in zip(grids, stored, strict=True)]
    return b"".join(parts + stored)
