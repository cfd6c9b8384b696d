"""NanoVDB grids in kdsl's own code: the byte layout (``layout``), a validating
reader (``read_grids``), a writer with the file codecs, and a NumPy builder of grids
from dense arrays, tiles or voxels. ``kdsl.Volume`` is built on them.
"""

from kdsl.geometry.nanovdb.grid_info import GridInfo
from kdsl.geometry.nanovdb.layout import Codec, GridClass, GridType, ValueLayout, value_layout

__all__ = ["Codec", "GridClass", "GridInfo", "GridType", "ValueLayout", "value_layout"]
