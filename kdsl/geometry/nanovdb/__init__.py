"""NanoVDB grids in kdsl's own code; ``kdsl.Volume`` is built on them.

- ``layout``: byte offsets and sizes (file, grid, tree, root, nodes), ``GridType``,
  ``GridClass``, ``Codec``, and ``value_layout(grid_type)`` for the offsets that depend
  on the value type;
- ``read_grids(file_or_bytes, verify_checksum=True) -> list[GridInfo]``: every grid of a
  file or raw buffer, validated (``grid_validation.parse_grid`` for one grid's bytes);
- ``GridInfo`` / ``FeatureInfo``: a validated grid's bytes, offsets, counts, transform,
  bounding boxes and blind data (feature arrays);
- ``write_nvdb(grids, codec) -> bytes``: a ``.nvdb`` file; ``codecs``: ZIP and Blosc;
- ``builder``: grid bytes from dense arrays, tiles or voxels (``build_grid``);
- ``checksum``: NanoVDB's two CRC-32s.

Errors are ``NanoVDBError`` (``NanoVDBCodecError`` for codecs), ``KdslError`` subclasses.
"""

from kdsl.geometry.nanovdb.errors import NanoVDBCodecError, NanoVDBError
from kdsl.geometry.nanovdb.grid_info import FeatureInfo, GridInfo
from kdsl.geometry.nanovdb.layout import Codec, GridClass, GridType, ValueLayout, value_layout
from kdsl.geometry.nanovdb.reader import read_grids
from kdsl.geometry.nanovdb.writer import write_nvdb

__all__ = [
    "Codec", "FeatureInfo", "GridClass", "GridInfo", "GridType", "NanoVDBCodecError",
    "NanoVDBError", "ValueLayout", "read_grids", "value_layout", "write_nvdb",
]  # fmt: skip
