"""``kdsl.Volume``: a sparse NanoVDB grid on one device, sampled from kernels by its id
(Warp's ``warp.Volume``).

A volume holds its grid's bytes in one device buffer of ``uint32`` words (``array()``
gives the same memory as bytes, as Warp's does) and, on the host, the grid's validated
``GridInfo`` (``kdsl.geometry.nanovdb``). Grids come from NanoVDB files or buffers
(``load_from_nvdb``, ``Volume(data)``) or from the NumPy builder (``load_from_numpy``,
``allocate``, ``allocate_by_tiles``, ``allocate_by_voxels``). Kernels read the grid
through the record ``kdsl.geometry.volume_record.make_volume_record`` makes, on first
use of ``id``. Topology never changes after construction (``volume_store`` writes
values only), so tile and voxel lists come from the host copy of the header and nodes.
"""

from __future__ import annotations

from typing import Any, ClassVar, Literal, NamedTuple

import numpy as np

from kdsl.errors import KdslTypeError
from kdsl.geometry.nanovdb.builder import (
    Feature,
    build_grid,
    leaves_from_dense,
    leaves_from_tiles,
    leaves_from_voxels,
)
from kdsl.geometry.nanovdb.checksum import grid_checksum
from kdsl.geometry.nanovdb.codecs import parse_codec
from kdsl.geometry.nanovdb.errors import NanoVDBError
from kdsl.geometry.nanovdb.grid_info import GridInfo
from kdsl.geometry.nanovdb.grid_validation import parse_grid
from kdsl.geometry.nanovdb.layout import (
    GRID_OFF_CHECKSUM,
    GRID_OFF_MAP,
    LEAF_OFF_VALUE_MASK,
    GridType,
)
from kdsl.geometry.nanovdb.reader import read_grids
from kdsl.geometry.nanovdb.writer import write_nvdb
from kdsl.geometry.volume_args import (
    VolumeError,
    grid_type_of_background,
    index_to_world,
    points_to_coords,
    vector3,
    voxel_sizes,
)
from kdsl.ir import types as T
from kdsl.runtime.array import array
from kdsl.runtime.device import get_device
from kdsl.types import class_of, mat33f, type_of, uint8, uint32, vec3f

__all__ = ["Volume", "VolumeError"]


def _build(*args: Any, **kwargs: Any) -> bytes:
    # In-memory grids carry no checksum (kernels may change their values, as in Warp);
    # save_to_nvdb computes one for the file.
    return build_grid(*args, checksum=False, **kwargs)


# NanoVDB type names (Warp's type_str) -> kdsl dtypes, for ``dtype`` and feature arrays
_DTYPES = {
    "float": T.F32, "double": T.F64, "int16": T.I16, "int32": T.I32, "int64": T.I64,
    "uint32": T.U32, "uint8": T.U8, "Half": T.F16,
    "Vec3f": T.VectorType(3, T.F32), "Vec3d": T.VectorType(3, T.F64),
    "Vec4f": T.VectorType(4, T.F32), "Vec4d": T.VectorType(4, T.F64),
    "Vec3u8": T.VectorType(3, T.U8), "Vec3u16": T.VectorType(3, T.U16),
}  # fmt: skip


class Volume:
    """A sparse volume: one NanoVDB grid (and any grids after it in its buffer) on a
    device. ``Volume(data)`` takes a kdsl ``uint8`` array holding raw grids; the class
    methods below build or load one."""

    #: Nearest-voxel sampling (``volume_sample*``'s ``sampling_mode``).
    CLOSEST: ClassVar[int] = 0
    #: Trilinear sampling.
    LINEAR: ClassVar[int] = 1

    class GridInfo(NamedTuple):
        """Grid metadata, as ``warp.Volume.GridInfo``."""

        name: str
        size_in_bytes: int
        grid_index: int
        grid_count: int
        type_str: str
        translation: Any
        transform_matrix: Any

    class FeatureArrayInfo(NamedTuple):
        """A feature (blind data) array's metadata, as ``warp.Volume.FeatureArrayInfo``."""

        name: str
        ptr: int
        value_size: int
        value_count: int
        type_str: str

    def __init__(self, data: array, copy: bool = True) -> None:
        """A volume of the raw grids in ``data`` (a 1-d kdsl ``uint8`` array, on the
        device the volume will live on). The grids are validated; their checksums are
        not (a live buffer's values may have been changed by kernels). ``copy`` is
        accepted for Warp's signature; the bytes are always copied."""
        if not isinstance(data, array) or type_of(data.dtype) != T.U8 or data.ndim != 1:
            raise KdslTypeError(f"Volume(data) needs a 1-d kdsl.array of uint8, not {data!r}")
        grids = read_grids(np.ascontiguousarray(data.numpy()).tobytes(), verify_checksum=False)
        self._init(grids, data.device)

    def _init(self, grids: list[GridInfo], device: Any) -> None:
        self.device = get_device(device)
        self._grids = grids
        self._info = grids[0]
        raw = grids[0].data if len(grids) == 1 else b"".join(g.data for g in grids)
        words = np.frombuffer(raw, dtype=np.uint32)
        self._words = array(words, dtype=uint32, device=self.device)
        self._bytes: array | None = None
        self._record: Any = None
        self._previous: Volume | None = None

    @classmethod
    def _of(cls, grids: list[GridInfo], device: Any) -> Volume:
        volume = cls.__new__(cls)
        volume._init(grids, device)
        return volume

    @classmethod
    def _built(cls, data: bytes, device: Any) -> Volume:
        return cls._of([parse_grid(data, "<built>", 0, verify_checksum=False)], device)

    # --- kernels ----------------------------------------------------------------------

    @property
    def id(self) -> int:
        """The volume's id (a ``uint64``) for kernels."""
        if self._record is None:
            from kdsl.geometry.volume_record import (
                make_volume_record,
            )  # lazy: DEVICE's module imports the stdlib

            self._record = make_volume_record(self, self._words, self._info, self.device)
        return self._record.id

    @property
    def info(self) -> GridInfo:
        """The grid's ``kdsl.geometry.nanovdb.GridInfo`` (offsets, counts, transform)."""
        return self._info

    def array(self) -> array:
        """The raw grid buffer (this grid and those after it) as a 1-d ``uint8`` array on
        the volume's device: the memory kernels read and ``volume_store`` writes."""
        if self._bytes is None:
            n = self._words.shape[0] * 4
            self._bytes = array(ptr=self._words.ptr, dtype=uint8, shape=n, device=self.device)
        return self._bytes

    # --- metadata ---------------------------------------------------------------------

    def get_grid_info(self) -> Volume.GridInfo:
        """The grid's name, size, index and count, value type and transform."""
        g = self._info
        # the float32 copy of the transform the grid holds, as Warp reports it
        single = np.frombuffer(g.data, "<f4", 21, GRID_OFF_MAP)
        return Volume.GridInfo(
            g.name, g.grid_size, g.grid_index, g.grid_count, g.type_str,
            vec3f(*single[18:21]), mat33f(*single[:9]),
        )  # fmt: skip

    @property
    def dtype(self) -> type | None:
        """The kdsl type of the values (``None`` for index grids)."""
        t = _DTYPES.get(self._info.type_str)
        return None if t is None else class_of(t)

    @property
    def is_index(self) -> bool:
        """Whether this is an index grid (values in feature arrays, not the tree)."""
        return self._info.is_index

    def get_voxel_size(self) -> tuple[float, float, float]:
        """The size of a voxel along each axis, in world units (float32 values)."""
        return tuple(float(np.float32(v)) for v in self._info.voxel_size)  # type: ignore[return-value]

    def get_tile_count(self) -> int:
        """The number of tiles (NanoVDB leaf nodes, 8^3 voxels each)."""
        return self._info.leaf_count

    def _indexes_active_only(self) -> bool:
        return self._info.grid_type in (GridType.ONINDEX, GridType.ONINDEXMASK)

    def get_voxel_count(self) -> int:
        """The number of voxels kernels index, as Warp counts them: the active voxels of
        an OnIndex grid, every voxel of every leaf (512 a tile) of any other grid."""
        if self._indexes_active_only():
            return self._info.active_voxel_count
        return 512 * self._info.leaf_count

    class ActiveStats(NamedTuple):
        """Active topology counts, as ``warp.Volume.ActiveStats``."""

        voxel_count: int
        leaf_node_count: int
        lower_node_count: int
        upper_node_count: int

    def get_active_stats(self) -> Volume.ActiveStats:
        """``get_voxel_count()`` and the leaf, lower and upper node counts."""
        g = self._info
        return Volume.ActiveStats(self.get_voxel_count(), g.leaf_count, g.lower_count,
                                  g.upper_count)  # fmt: skip

    @property
    def is_rebuildable(self) -> bool:
        """Always ``False``: kdsl volumes have no reserved capacity for ``rebuild``."""
        return False

    def _leaf_bytes(self) -> np.ndarray:
        g = self._info
        start, size = g.leaf_offset, g.layout.leaf_size
        return np.frombuffer(g.data, np.uint8, g.leaf_count * size, start).reshape(-1, size)

    def _tile_origins(self) -> np.ndarray:
        leaves = np.ascontiguousarray(self._leaf_bytes()[:, :12])
        return leaves.view("<i4").reshape(-1, 3) & ~7

    def get_tiles(self, out: array | None = None) -> array:
        """The index coordinates of every tile's first voxel, in leaf order, as a
        ``(tile_count, 3)`` int32 array (or into ``out``)."""
        return self._output(self._tile_origins(), out, "get_tiles")

    def get_voxels(self, out: array | None = None) -> array:
        """The index coordinates of the ``get_voxel_count()`` voxels (an OnIndex grid's
        active voxels, any other grid's leaf voxels, active or not, as Warp lists them),
        leaf by leaf and x-major within a leaf, as a ``(voxel_count, 3)`` int32 array (or
        into ``out``)."""
        if self._indexes_active_only():
            masks = self._leaf_bytes()[:, LEAF_OFF_VALUE_MASK : LEAF_OFF_VALUE_MASK + 64]
            leaf, slot = np.nonzero(np.unpackbits(masks, axis=1, bitorder="little"))
        else:
            leaf, slot = np.divmod(np.arange(512 * self._info.leaf_count), 512)
        local = np.stack([slot >> 6, (slot >> 3) & 7, slot & 7], axis=1)
        return self._output(self._tile_origins()[leaf] + local, out, "get_voxels")

    def _output(self, coords: np.ndarray, out: array | None, name: str) -> array:
        coords = coords.astype(np.int32).reshape(-1, 3)
        if out is None:
            return array(coords, dtype=type_of(np.int32), device=self.device)
        if not isinstance(out, array) or out.device != self.device:
            raise VolumeError(f"Volume.{name} out must be a kdsl.array on {self.device}")
        t = type_of(out.dtype)
        fits = (t == T.VectorType(3, T.I32) and out.ndim == 1) or (
            t == T.I32 and out.ndim == 2 and out.shape[1] == 3
        )
        if not fits or out.shape[0] < len(coords):
            raise VolumeError(f"Volume.{name} out must hold at least {len(coords)} vec3i "
                              f"(or rows of 3 int32), not {out.shape} of {t}")  # fmt: skip
        host = np.array(out.numpy()).reshape(-1, 3)
        host[: len(coords)] = coords
        return out.assign(host.reshape(out.numpy().shape))

    # --- feature arrays (blind data) --------------------------------------------------

    def get_feature_array_count(self) -> int:
        """The number of feature (blind data) arrays stored with the grid."""
        return len(self._info.features)

    def get_feature_array_info(self, feature_index: int) -> Volume.FeatureArrayInfo:
        """The name, address, value size and count, and type of feature array
        ``feature_index``."""
        f = self._feature(feature_index)
        return Volume.FeatureArrayInfo(f.name, self._words.ptr + f.offset, f.value_size,
                                       f.value_count, f.type_str)  # fmt: skip

    def _feature(self, i: int):
        if not isinstance(i, int | np.integer) or not 0 <= i < len(self._info.features):
            raise VolumeError(f"Volume has {len(self._info.features)} feature arrays, no "
                              f"feature array {i!r}")  # fmt: skip
        return self._info.features[int(i)]

    def feature_array(self, feature_index: int, dtype: Any = None) -> array:
        """Feature array ``feature_index`` as a 1-d array aliasing the volume's memory
        (``dtype`` from its metadata unless given; any array can be seen as bytes, and a
        byte array as any type whose size divides it)."""
        f = self._feature(feature_index)
        t = type_of(dtype) if dtype is not None else _DTYPES.get(f.type_str, T.U8)
        size = T.storage_dtype(t).itemsize
        count, value_size = f.value_count, f.value_size
        if size == 1:
            count, value_size = count * value_size, 1
        elif value_size == 1 and count % size == 0:
            count, value_size = count // size, size
        if size != value_size:
            raise VolumeError(f"Volume feature array {f.name!r} holds values of {value_size} "
                              f"bytes, not {size} ({t})")  # fmt: skip
        return array(ptr=self._words.ptr + f.offset, dtype=class_of(t), shape=count,
                     device=self.device)  # fmt: skip

    # --- files --------------------------------------------------------------------------

    @classmethod
    def load_from_nvdb(cls, file_or_buffer: Any, device: Any = None) -> Volume:
        """A volume of the grids in a NanoVDB file (a path, a binary file object or a
        bytes-like buffer; uncompressed, ZIP or Blosc) or raw grid buffer, checked and
        with checksums verified; the volume is the first grid (``load_next_grid``)."""
        return cls._of(read_grids(file_or_buffer), device)

    def load_next_grid(self) -> Volume | None:
        """A volume of the next grid of this volume's buffer, or ``None``."""
        if len(self._grids) < 2:
            return None
        volume = Volume._of(self._grids[1:], self.device)
        volume._previous = self
        return volume

    def _current_grids(self) -> list[GridInfo]:
        """The grids as they are now on the device (kernels may have stored values),
        each with a full checksum of what it holds now."""
        data = np.ascontiguousarray(self._words.numpy()).view(np.uint8)
        out, pos = [], 0
        for g in self._grids:
            raw = bytearray(data[pos : pos + g.grid_size].tobytes())
            pos += g.grid_size
            spans = ((g.upper_offset, g.upper_count, g.layout.upper_size),
                     (g.lower_offset, g.lower_count, g.layout.lower_size),
                     (g.leaf_offset, g.leaf_count, g.layout.leaf_size))  # fmt: skip
            checksum = grid_checksum(bytes(raw), g.version, spans)
            raw[GRID_OFF_CHECKSUM : GRID_OFF_CHECKSUM + 8] = checksum.to_bytes(8, "little")
            out.append(parse_grid(bytes(raw), "<volume>", len(out), verify_checksum=False))
        return out

    def save_to_nvdb(self, path: Any, codec: Literal["none", "zip", "blosc"] = "none") -> Any:
        """Write this volume's grids to a ``.nvdb`` file (a path or a binary file
        object) under ``codec`` ("none", "zip", or "blosc" with the ``blosc`` package);
        returns ``path``."""
        data = write_nvdb(self._current_grids(), parse_codec(codec), str(path))
        if hasattr(path, "write"):
            path.write(data)
            return path
        try:
            with open(path, "wb") as f:
                f.write(data)
        except OSError as err:
            raise NanoVDBError(f"{path}: cannot write NanoVDB file: {err.strerror}") from None
        return path

    # --- construction -----------------------------------------------------------------

    @classmethod
    def load_from_numpy(cls, ndarray: Any, min_world: Any = (0.0, 0.0, 0.0),
                        voxel_size: Any = 1.0, bg_value: Any = 0.0,
                        device: Any = None) -> Volume:  # fmt: skip
        """A volume of a dense array: every voxel of ``ndarray`` (X, Y, Z) active (padded
        to whole 8^3 tiles with ``bg_value``), voxel ``[0, 0, 0]`` at world ``min_world``.
        A ``bg_value`` with a length makes a vec3f grid of an (X, Y, Z, 3) array, a Python
        int an int32 grid, anything else a float32 grid (Warp's rules)."""
        sizes, origin = voxel_sizes(voxel_size), vector3(min_world, "min_world")
        a = np.asarray(ndarray)
        if hasattr(bg_value, "__len__"):
            grid_type, dtype, ndim = GridType.VEC3F, np.float32, 4
            if a.ndim != 4 or a.shape[3] != 3:
                raise VolumeError(f"Volume.load_from_numpy: a vector bg_value needs an (X, Y, "
                                  f"Z, 3) array, not shape {a.shape}")  # fmt: skip
        else:
            is_int = isinstance(bg_value, int) and not isinstance(bg_value, bool)
            grid_type = GridType.INT32 if is_int else GridType.FLOAT
            dtype, ndim = (np.int32 if is_int else np.float32), 3
        if a.ndim != ndim or 0 in a.shape:
            raise VolumeError(f"Volume.load_from_numpy needs a non-empty {ndim}-d array, not "
                              f"shape {a.shape}")  # fmt: skip
        bg = np.asarray(bg_value, dtype=dtype)
        leaves = leaves_from_dense(a.astype(dtype, copy=False), (0, 0, 0), bg)
        return cls._built(_build(leaves, grid_type, bg, np.diag(sizes), origin), device)

    @classmethod
    def allocate(cls, min: Any, max: Any, voxel_size: Any, bg_value: Any = 0.0,
                 translation: Any = (0.0, 0.0, 0.0), points_in_world_space: bool = False,
                 device: Any = None) -> Volume:  # fmt: skip
        """A volume whose tiles cover voxels ``min`` to ``max`` (inclusive; world
        positions when ``points_in_world_space``, rounded to voxels as Warp does), every
        voxel active at ``bg_value``."""
        sizes, shift = voxel_sizes(voxel_size), vector3(translation, "translation")
        lo, hi = vector3(min, "min"), vector3(max, "max")
        if points_in_world_space:
            vs = np.asarray(sizes, dtype=np.float32)
            lo = np.around((lo.astype(np.float32) - shift) / vs)
            hi = np.around((hi.astype(np.float32) - shift) / vs)
        t_lo, t_hi = lo.astype(np.int64) // 8, hi.astype(np.int64) // 8
        if (t_hi < t_lo).any() or np.prod(t_hi - t_lo + 1) > 1 << 24:
            raise VolumeError(f"Volume.allocate: min {list(lo)} and max {list(hi)} give "
                              f"no tiles or more than 2**24")  # fmt: skip
        axes = [np.arange(a, b + 1) for a, b in zip(t_lo, t_hi, strict=True)]
        tiles = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3) * 8
        return cls._from_tiles(tiles, np.diag(sizes), shift, bg_value, device)

    @classmethod
    def _from_tiles(cls, tiles, mat, shift, bg_value, device) -> Volume:
        grid_type = grid_type_of_background(bg_value)
        index = grid_type == GridType.ONINDEX
        if index:  # whole tiles index every voxel: an Index grid, as Warp makes them
            grid_type = GridType.INDEX
        leaves = leaves_from_tiles(tiles, None if index else bg_value, index=index)
        return cls._built(_build(leaves, grid_type, bg_value, mat, shift), device)

    @classmethod
    def allocate_by_tiles(cls, tile_points: array, voxel_size: Any = None, bg_value: Any = 0.0,
                          translation: Any = (0.0, 0.0, 0.0), device: Any = None,
                          transform: Any = None, **rebuild: Any) -> Volume:  # fmt: skip
        """A volume with an active 8^3 tile at each of ``tile_points`` (int32 index
        coordinates, or float32 world positions), every voxel at ``bg_value`` (``None``
        makes an Index grid)."""
        _refuse_rebuild(rebuild)
        mat, shift = index_to_world(voxel_size, transform), vector3(translation, "translation")
        coords = points_to_coords(tile_points, mat, shift, "tile_points")
        return cls._from_tiles(coords, mat, shift, bg_value, device)

    @classmethod
    def allocate_by_voxels(cls, voxel_points: array, voxel_size: Any = None,
                           translation: Any = (0.0, 0.0, 0.0), device: Any = None,
                           transform: Any = None, **rebuild: Any) -> Volume:  # fmt: skip
        """An OnIndex volume with exactly the voxels of ``voxel_points`` active (int32
        index coordinates, or float32 world positions; repeats allowed)."""
        _refuse_rebuild(rebuild)
        mat, shift = index_to_world(voxel_size, transform), vector3(translation, "translation")
        coords = points_to_coords(voxel_points, mat, shift, "voxel_points")
        data = _build(leaves_from_voxels(coords, None, None), GridType.ONINDEX, None, mat,
                          shift)  # fmt: skip
        return cls._built(data, device)

    @classmethod
    def from_index_grid(cls, index_volume: Volume, features: dict[str, Any],
                        device: Any = None) -> Volume:  # fmt: skip
        """An index volume like ``index_volume`` carrying ``features``: name -> NumPy
        array of one value per index (``index_count`` rows, row 0 the background), each
        stored as a feature (blind data) array."""
        g = index_volume.info
        if not g.is_index:
            raise VolumeError("Volume.from_index_grid needs an index volume")
        items = []
        for name, values in features.items():
            values = np.ascontiguousarray(values)
            kind = _feature_grid_type(values)
            if len(values) != g.index_count:
                raise VolumeError(f"Volume feature {name!r} has {len(values)} values; the "
                                  f"grid indexes {g.index_count}")  # fmt: skip
            items.append(Feature(name, values, kind))
        coords = index_volume.get_voxels().numpy()
        data = _build(leaves_from_voxels(coords, None, None), GridType.ONINDEX, None,
                          g.index_to_world, g.translation, g.name, features=items)  # fmt: skip
        return cls._built(data, device or index_volume.device)


_FEATURE_TYPES = {
    ("<f4", ()): GridType.FLOAT, ("<f8", ()): GridType.DOUBLE, ("<i4", ()): GridType.INT32,
    ("<i8", ()): GridType.INT64, ("<u4", ()): GridType.UINT32,
    ("<f4", (3,)): GridType.VEC3F, ("<f8", (3,)): GridType.VEC3D,
    ("<f4", (4,)): GridType.VEC4F, ("<f8", (4,)): GridType.VEC4D,
}  # fmt: skip


def _feature_grid_type(values: np.ndarray) -> GridType:
    key = (values.dtype.newbyteorder("<").str, values.shape[1:])
    if key not in _FEATURE_TYPES:
        raise KdslTypeError(f"Volume feature arrays hold float32/64, int32/64, uint32 or "
                            f"vec3/vec4 values, not {values.dtype} of shape {values.shape}")  # fmt: skip
    return _FEATURE_TYPES[key]


def _refuse_rebuild(options: dict[str, Any]) -> None:
    if options:
        raise VolumeError(f"Volume: rebuildable volumes are not supported (got "
                          f"{sorted(options)})")  # fmt: skip
