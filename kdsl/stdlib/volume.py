"""kdsl standard library: sparse volume sampling (Warp's ``volume_*``), in kdsl.

A ``kdsl.Volume`` is a NanoVDB grid held as one array of 32-bit words on its device.
Kernels reach it through its record (``VolumeRecord``, written by
``kdsl.geometry.volume_record.make_volume_record``): the words, and the word offsets
of the parts every lookup needs (the root, its tiles, the value tables of each node
level), plus the grid's index-to-world map in float32 and float64.

A lookup descends NanoVDB's tree as PNanoVDB does: find the root tile whose key
matches the voxel's 4096^3 region (a linear search of the root's table), then test
the child mask of the upper (32^3) and lower (16^3) internal nodes; a voxel whose
node has no child there takes that node's tile value, one outside every root tile
the background. ``_locate`` gives the word of the value (or of the leaf) and the level
it was found at.

Trilinear sampling reads the 8 voxels around a point. The tree is descended once for
the base voxel and once more for each other 8^3 leaf region the corners reach (a
corner one voxel up an axis is in the next region when the base is the last voxel of
its region on that axis): one descent for about 2 samples in 3 ((7/8)^3), at most 8.

Value types (Warp's): int32, int64, uint32, float32, float64, vec3f, vec3d, vec4f,
vec4d. Each sampling function is generic over the value type through a *witness*
argument (a zero of the type, which the ``dtype=`` builtins of
``kdsl.frontend.builtins_volume`` pass): overloads by the witness's type read,
scale and store the value. Besides the record at ``id``, every volume has a second,
small record whose struct type names its value type (``VolumeFloat32``...; ``typed``
in ``VolumeRecord`` is its id): typed reads take the words from it, so a debug build's
``kd.check_record`` stops a kernel that samples an int32 grid with
``volume_sample_f``; a release build gives zero then, as Warp does.
"""

from typing import Any

import kdsl as wp
from kdsl.frontend.inout import inout
from kdsl.frontend.kernel import func

__kdsl_group__ = "geometry"

__all__ = [
    "VolumeRecord", "volume_index_to_world", "volume_index_to_world_dir",
    "volume_lookup_f", "volume_lookup_i", "volume_lookup_index", "volume_lookup_v",
    "volume_sample_f", "volume_sample_grad_f", "volume_sample_i", "volume_sample_local",
    "volume_sample_v", "volume_sample_world", "volume_store_f", "volume_store_i",
    "volume_store_v", "volume_transform", "volume_transform_inv", "volume_voxel_count",
    "volume_world_to_index", "volume_world_to_index_dir",
]  # fmt: skip

#: Sampling modes, Warp's values (``kdsl.Volume.CLOSEST`` / ``LINEAR``).
CLOSEST = 0
LINEAR = 1

#: Levels ``_locate`` reports: a leaf voxel, a tile of a lower node, of an upper node,
#: a root tile's value, the background.
LEAF, LOWER_TILE, UPPER_TILE, ROOT_TILE, BACKGROUND = 0, 1, 2, 3, 4

# Word offsets inside nodes (NanoVDB's byte offsets / 4; see kdsl.geometry.nanovdb.layout).
_UPPER_CHILD_MASK = 1032
_LOWER_CHILD_MASK = 136
_LEAF_VALUE_MASK = 4
_LEAF_INDEX_OFFSET = 20
_LEAF_PREFIX_SUM = 22

#: How an index is found in a leaf (``VolumeRecord.index_kind``): every leaf voxel has
#: one (``leaf number * 512 + n + 1``, grids of values: Warp's rule), the leaf stores
#: its first index (Index, IndexMask), or only active voxels have one (OnIndex...).
INDEX_DENSE, INDEX_LEAF_OFFSET, INDEX_ACTIVE = 0, 1, 2


@wp.struct
class VolumeRecord:
    """The record of a ``kdsl.Volume``: the grid's words and word offsets (see the
    module docstring; ``make_volume_record`` fills it)."""

    tag: wp.uint64
    #: The grid, as little-endian 32-bit words (NanoVDB's buffer).
    words: wp.array(dtype=wp.uint32)
    #: The id of the volume's typed record (its value type's ``Volume<Type>``).
    typed: wp.uint64
    grid_type: wp.int32
    #: Word of the RootData, of its first tile, words per tile, a tile value's word
    #: within its tile, and the word of the background value.
    root: wp.int32
    first_tile: wp.int32
    tile_words: wp.int32
    tile_value: wp.int32
    tile_count: wp.int32
    background: wp.int32
    #: Word offsets of the value/child tables of upper and lower nodes, words per entry.
    upper_table: wp.int32
    lower_table: wp.int32
    table_words: wp.int32
    #: Word offset of a leaf's value table, words per value (0 for index grids), word of
    #: the first leaf and words per leaf.
    leaf_table: wp.int32
    value_words: wp.int32
    first_leaf: wp.int32
    leaf_words: wp.int32
    index_kind: wp.int32
    #: Warp's ``volume_voxel_count``.
    voxel_count: wp.int32
    #: Index-to-world map: ``world = mat @ index + vec``; ``invmat`` its inverse.
    matf: wp.mat33
    invmatf: wp.mat33
    vecf: wp.vec3
    matd: wp.mat33d
    invmatd: wp.mat33d
    vecd: wp.vec3d


# -- the tree --------------------------------------------------------------------------


@func
def _offset_words(lo: wp.uint32, hi: wp.uint32) -> int:
    """A NanoVDB child offset (an int64 of bytes, low word first) in words."""
    return int((lo >> wp.uint32(2)) | (hi << wp.uint32(30)))


@func
def _bit(words: wp.array(dtype=wp.uint32), mask: int, n: int) -> bool:
    """Bit ``n`` of the bit mask starting at word ``mask``."""
    return ((words[mask + (n >> 5)] >> wp.uint32(n & 31)) & wp.uint32(1)) != wp.uint32(0)


@func
def _locate(id: wp.uint64, i: int, j: int, k: int) -> wp.vec2i:
    """``(word, level)`` of voxel ``(i, j, k)``: at ``LEAF``, the word of its leaf node;
    at a tile level or ``BACKGROUND``, the word of the value that covers it."""
    rec = wp.object_record(id, VolumeRecord)
    words = rec.words
    # The root key of the voxel's 4096^3 region, as two words (x in the top bits).
    iu = wp.uint32(i) >> wp.uint32(12)
    ju = wp.uint32(j) >> wp.uint32(12)
    ku = wp.uint32(k) >> wp.uint32(12)
    key_lo = ku | (ju << wp.uint32(21))
    key_hi = (ju >> wp.uint32(11)) | (iu << wp.uint32(10))
    tile = rec.first_tile
    left = rec.tile_count  # -1 once found
    while left > 0:
        if words[tile] == key_lo and words[tile + 1] == key_hi:
            left = -1
        else:
            tile = tile + rec.tile_words
            left = left - 1
    if left == 0:
        return wp.vec2i(rec.background, BACKGROUND)
    child_lo = words[tile + 2]
    child_hi = words[tile + 3]
    if child_lo == wp.uint32(0) and child_hi == wp.uint32(0):
        return wp.vec2i(tile + rec.tile_value, ROOT_TILE)
    upper = rec.root + _offset_words(child_lo, child_hi)
    n = (((i & 4095) >> 7) << 10) | (((j & 4095) >> 7) << 5) | ((k & 4095) >> 7)
    entry = upper + rec.upper_table + rec.table_words * n
    if not _bit(words, upper + _UPPER_CHILD_MASK, n):
        return wp.vec2i(entry, UPPER_TILE)
    lower = upper + _offset_words(words[entry], words[entry + 1])
    n = (((i & 127) >> 3) << 8) | (((j & 127) >> 3) << 4) | ((k & 127) >> 3)
    entry = lower + rec.lower_table + rec.table_words * n
    if not _bit(words, lower + _LOWER_CHILD_MASK, n):
        return wp.vec2i(entry, LOWER_TILE)
    return wp.vec2i(lower + _offset_words(words[entry], words[entry + 1]), LEAF)


@wp.func_grad(_locate)
def _adj_locate(id: wp.uint64, i: int, j: int, k: int, adj_ret: wp.vec2i):
    """No gradient (integers only): the backward pass replays the descent whole."""
    pass


@func
def _leaf_offset(i: int, j: int, k: int) -> int:
    """Voxel ``(i, j, k)``'s position in its leaf (z fastest)."""
    return ((i & 7) << 6) | ((j & 7) << 3) | (k & 7)


@func
def _value_word(rec: VolumeRecord, loc: wp.vec2i, i: int, j: int, k: int) -> int:
    """The word of voxel ``(i, j, k)``'s value, found at ``loc`` (``_locate``)."""
    if loc[1] == LEAF:
        return loc[0] + rec.leaf_table + rec.value_words * _leaf_offset(i, j, k)
    return loc[0]


@func
def _voxel_index(rec: VolumeRecord, loc: wp.vec2i, i: int, j: int, k: int) -> wp.int64:
    """The index of voxel ``(i, j, k)`` in a per-voxel array, plus one (0: none), as
    PNanoVDB numbers them: only leaf voxels have one."""
    if loc[1] != LEAF:
        return wp.int64(0)
    words = rec.words
    leaf = loc[0]
    n = _leaf_offset(i, j, k)
    if rec.index_kind == INDEX_DENSE:
        return wp.int64((leaf - rec.first_leaf) // rec.leaf_words) * wp.int64(512) + wp.int64(n + 1)
    first = _word64(words, leaf + _LEAF_INDEX_OFFSET)
    if rec.index_kind == INDEX_LEAF_OFFSET:
        return wp.int64(first) + wp.int64(n)
    if not _bit(words, leaf + _LEAF_VALUE_MASK, n):
        return wp.int64(0)
    # Active voxels before n: those of n's 64-bit mask word, plus the leaf's running
    # count of the words before it (7 9-bit fields).
    word = n >> 6
    lo = words[leaf + _LEAF_VALUE_MASK + 2 * word]
    hi = words[leaf + _LEAF_VALUE_MASK + 2 * word + 1]
    below = wp.uint32(1) << wp.uint32(n & 31)
    count = 0
    if (n & 32) != 0:
        count = wp.bit_count(lo) + wp.bit_count(hi & (below - wp.uint32(1)))
    else:
        count = wp.bit_count(lo & (below - wp.uint32(1)))
    if word > 0:
        sums = _word64(words, leaf + _LEAF_PREFIX_SUM)
        count = count + int((sums >> wp.uint64(9 * (word - 1))) & wp.uint64(511))
    return wp.int64(first) + wp.int64(count)


# -- values by type --------------------------------------------------------------------


@func
def _word64(words: wp.array(dtype=wp.uint32), w: int) -> wp.uint64:
    return (wp.uint64(words[w + 1]) << wp.uint64(32)) | wp.uint64(words[w])


@func
def _load(words: wp.array(dtype=wp.uint32), w: int, like: wp.float32) -> wp.float32:
    return wp.cast(words[w], wp.float32)


@func
def _load(words: wp.array(dtype=wp.uint32), w: int, like: wp.int32) -> wp.int32:
    return wp.cast(words[w], wp.int32)


@func
def _load(words: wp.array(dtype=wp.uint32), w: int, like: wp.uint32) -> wp.uint32:
    return words[w]


@func
def _load(words: wp.array(dtype=wp.uint32), w: int, like: wp.float64) -> wp.float64:
    return wp.cast(_word64(words, w), wp.float64)


@func
def _load(words: wp.array(dtype=wp.uint32), w: int, like: wp.int64) -> wp.int64:
    return wp.cast(_word64(words, w), wp.int64)


@func
def _load(words: wp.array(dtype=wp.uint32), w: int, like: wp.vec3) -> wp.vec3:
    s = like[0]
    return wp.vec3(_load(words, w, s), _load(words, w + 1, s), _load(words, w + 2, s))


@func
def _load(words: wp.array(dtype=wp.uint32), w: int, like: wp.vec3d) -> wp.vec3d:
    s = like[0]
    return wp.vec3d(_load(words, w, s), _load(words, w + 2, s), _load(words, w + 4, s))


@func
def _load(words: wp.array(dtype=wp.uint32), w: int, like: wp.vec4) -> wp.vec4:
    s = like[0]
    return wp.vec4(_load(words, w, s), _load(words, w + 1, s), _load(words, w + 2, s),
                   _load(words, w + 3, s))  # fmt: skip


@func
def _load(words: wp.array(dtype=wp.uint32), w: int, like: wp.vec4d) -> wp.vec4d:
    s = like[0]
    return wp.vec4d(_load(words, w, s), _load(words, w + 2, s), _load(words, w + 4, s),
                    _load(words, w + 6, s))  # fmt: skip


@func
def _put(words: wp.array(dtype=wp.uint32), w: int, bits: wp.uint32):
    words[w] = bits


@func
def _put(words: wp.array(dtype=wp.uint32), w: int, bits: wp.uint64):
    words[w] = wp.uint32(bits & wp.uint64(0xFFFFFFFF))
    words[w + 1] = wp.uint32(bits >> wp.uint64(32))


def _define_stores(value: Any, bits: Any, parts: int, stride: int) -> Any:
    """The ``_store`` overload for ``value``: scalars as their bits (``bits``, one or two
    words), vectors as ``parts`` scalars ``stride`` words apart."""
    if parts == 1:

        @func
        def _store(words: wp.array(dtype=wp.uint32), w: int, value: value):
            _put(words, w, wp.cast(value, bits))

    else:

        @func
        def _store(words: wp.array(dtype=wp.uint32), w: int, value: value):
            for c in range(parts):
                _store(words, w + stride * c, value[c])

    return _store


for _value, _bits, _parts, _stride in (
    (wp.float32, wp.uint32, 1, 1), (wp.int32, wp.uint32, 1, 1), (wp.uint32, wp.uint32, 1, 1),
    (wp.float64, wp.uint64, 1, 2), (wp.int64, wp.uint64, 1, 2), (wp.vec3, None, 3, 1),
    (wp.vec3d, None, 3, 2), (wp.vec4, None, 4, 1), (wp.vec4d, None, 4, 2),
):  # fmt: skip
    _store = _define_stores(_value, _bits, _parts, _stride)


@wp.struct
class _Words:
    """A grid's words, read as values of the grid's type (the generic samplers take this
    where the index samplers take a per-voxel array)."""

    words: wp.array(dtype=wp.uint32)


def _value_records() -> dict[int, type]:
    """The typed record struct of each value type, by NanoVDB grid type number."""

    def record(name: str) -> type:
        cls = type(name, (), {
            "__annotations__": {"tag": wp.uint64, "words": wp.array(dtype=wp.uint32)},
            "__doc__": f"The typed record of a volume of {name[6:]} values (see "
                       "``kdsl.stdlib.volume``).",
            "__module__": __name__,
        })  # fmt: skip
        return wp.struct(cls)

    names = {1: "Float32", 2: "Float64", 4: "Int32", 5: "Int64", 6: "Vec3f", 7: "Vec3d",
             10: "UInt32", 17: "Vec4f", 18: "Vec4d"}  # fmt: skip
    return {gt: record(f"Volume{name}") for gt, name in names.items()}


#: Grid type -> the struct of the typed record of a volume of that type. Every other
#: grid type (index grids, half, ...) has a ``VolumeOther`` record.
VALUE_RECORDS = _value_records()
VolumeOther = wp.struct(type("VolumeOther", (), {
    "__annotations__": {"tag": wp.uint64, "words": wp.array(dtype=wp.uint32)},
    "__doc__": "The typed record of a volume whose values kernels cannot read as a type "
               "(index grids, half...).",
    "__module__": __name__,
}))  # fmt: skip

_MAT43F = wp.matrix(shape=(4, 3), dtype=wp.float32)
_MAT43D = wp.matrix(shape=(4, 3), dtype=wp.float64)


def _define_value_type(value: Any, grid_type: int, scalar: Any, grad: Any) -> tuple:
    """The overloads for one value type: its grid type, its typed words, a value scaled by
    a trilinear weight and the gradient term of one corner (Warp's arithmetic: the weight
    is converted to the value's scalar type first, so integer grids truncate it)."""
    typed = VALUE_RECORDS[grid_type]

    @func
    def _grid_type_of(like: value) -> int:
        return grid_type

    @func
    def _typed_words(rec: VolumeRecord, like: value) -> _Words:
        return _Words(wp.object_record(rec.typed, typed).words)

    @func
    def _scaled(w: float, v: value) -> value:
        return scalar(w) * v

    if grad is _MAT43F or grad is _MAT43D or grad is wp.mat33 or grad is wp.mat33d:

        @func
        def _outer(v: value, dw: wp.vec3) -> grad:
            return wp.outer(v, wp.vector(scalar(dw[0]), scalar(dw[1]), scalar(dw[2])))

    else:

        @func
        def _outer(v: value, dw: wp.vec3) -> grad:
            return grad(scalar(dw[0]), scalar(dw[1]), scalar(dw[2])) * v

    return _grid_type_of, _typed_words, _scaled, _outer


for _spec in (
    (wp.float32, 1, wp.float32, wp.vec3), (wp.float64, 2, wp.float64, wp.vec3d),
    (wp.int32, 4, wp.int32, wp.vec3i), (wp.int64, 5, wp.int64, wp.vec3l),
    (wp.vec3, 6, wp.float32, wp.mat33), (wp.vec3d, 7, wp.float64, wp.mat33d),
    (wp.uint32, 10, wp.uint32, wp.vec3ui), (wp.vec4, 17, wp.float32, _MAT43F),
    (wp.vec4d, 18, wp.float64, _MAT43D),
):  # fmt: skip
    _grid_type_of, _typed_words, _scaled, _outer = _define_value_type(*_spec)


# -- sampling ----------------------------------------------------------------------------


@func
def _read(rec: VolumeRecord, loc: wp.vec2i, i: int, j: int, k: int, src: _Words, like: Any):
    """The value of voxel ``(i, j, k)`` (found at ``loc``) of a grid of values."""
    return _load(src.words, _value_word(rec, loc, i, j, k), like)


@func
def _read(
    rec: VolumeRecord, loc: wp.vec2i, i: int, j: int, k: int, data: wp.array(dtype=Any),
    background: Any,
):  # fmt: skip
    """The value of voxel ``(i, j, k)`` in the per-voxel array ``data`` (``background``
    where the voxel has no index)."""
    n = _voxel_index(rec, loc, i, j, k)
    if n > wp.int64(0):
        return data[n - wp.int64(1)]
    return background


@func
def _region(id: wp.uint64, moved: bool, i: int, j: int, k: int, same: wp.vec2i) -> wp.vec2i:
    """Where voxel ``(i, j, k)`` is found: a new descent when it ``moved`` to another leaf
    region than the corner whose ``_locate`` is ``same``, else that."""
    if moved:
        return _locate(id, i, j, k)
    return same


@func
def _closest(id: wp.uint64, uvw: wp.vec3, src: Any, extra: Any):
    """The value of the voxel nearest ``uvw`` (halfway rounds away from zero)."""
    rec = wp.object_record(id, VolumeRecord)
    # Float-to-int casts saturate (NaN gives 0) on every backend (docs/semantics.md).
    i = int(wp.round(uvw[0]))
    j = int(wp.round(uvw[1]))
    k = int(wp.round(uvw[2]))
    return _read(rec, _locate(id, i, j, k), i, j, k, src, extra)


@func
def _trilinear(id: wp.uint64, uvw: wp.vec3, src: Any, extra: Any):
    """The trilinear interpolant at ``uvw`` and its gradient with respect to ``uvw``,
    with Warp's arithmetic (float32 weights, corners summed in Warp's order). Between
    cells the gradient is the positive side's."""
    rec = wp.object_record(id, VolumeRecord)
    f = wp.floor(uvw)
    i = int(f[0])
    j = int(f[1])
    k = int(f[2])
    x1 = uvw[0] - f[0]
    y1 = uvw[1] - f[1]
    z1 = uvw[2] - f[2]
    x0 = 1.0 - x1
    y0 = 1.0 - y1
    z0 = 1.0 - z1
    # A corner one voxel up an axis leaves the base's 8^3 leaf region when the base is
    # the region's last voxel on that axis. Each region is descended once: a corner's
    # region is the one of the corner that moves only along the axes that cross.
    mx = (i & 7) == 7
    my = (j & 7) == 7
    mz = (k & 7) == 7
    r000 = _locate(id, i, j, k)
    r001 = _region(id, mz, i, j, k + 1, r000)
    r010 = _region(id, my, i, j + 1, k, r000)
    r100 = _region(id, mx, i + 1, j, k, r000)
    r011 = _region(id, my and mz, i, j + 1, k + 1, wp.where(my, r010, r001))
    r101 = _region(id, mx and mz, i + 1, j, k + 1, wp.where(mx, r100, r001))
    r110 = _region(id, mx and my, i + 1, j + 1, k, wp.where(mx, r100, r010))
    r111 = _region(id, mx and my and mz, i + 1, j + 1, k + 1,
                   wp.where(mx, wp.where(my, r110, r101), wp.where(my, r011, r001)))  # fmt: skip
    v = _read(rec, r000, i, j, k, src, extra)
    val = _scaled(x0 * y0 * z0, v)
    grad = _outer(v, wp.vec3(-y0 * z0, -x0 * z0, -x0 * y0))
    v = _read(rec, r001, i, j, k + 1, src, extra)
    val = val + _scaled(x0 * y0 * z1, v)
    grad = grad + _outer(v, wp.vec3(-y0 * z1, -x0 * z1, x0 * y0))
    v = _read(rec, r010, i, j + 1, k, src, extra)
    val = val + _scaled(x0 * y1 * z0, v)
    grad = grad + _outer(v, wp.vec3(-y1 * z0, x0 * z0, -x0 * y1))
    v = _read(rec, r011, i, j + 1, k + 1, src, extra)
    val = val + _scaled(x0 * y1 * z1, v)
    grad = grad + _outer(v, wp.vec3(-y1 * z1, x0 * z1, x0 * y1))
    v = _read(rec, r100, i + 1, j, k, src, extra)
    val = val + _scaled(x1 * y0 * z0, v)
    grad = grad + _outer(v, wp.vec3(y0 * z0, -x1 * z0, -x1 * y0))
    v = _read(rec, r101, i + 1, j, k + 1, src, extra)
    val = val + _scaled(x1 * y0 * z1, v)
    grad = grad + _outer(v, wp.vec3(y0 * z1, -x1 * z1, x1 * y0))
    v = _read(rec, r110, i + 1, j + 1, k, src, extra)
    val = val + _scaled(x1 * y1 * z0, v)
    grad = grad + _outer(v, wp.vec3(y1 * z0, x1 * z0, -x1 * y1))
    v = _read(rec, r111, i + 1, j + 1, k + 1, src, extra)
    val = val + _scaled(x1 * y1 * z1, v)
    grad = grad + _outer(v, wp.vec3(y1 * z1, x1 * z1, x1 * y1))
    return val, grad


@func
def _sample(id: wp.uint64, uvw: wp.vec3, sampling_mode: int, src: Any, extra: Any, zero: Any):
    """``volume_sample``'s value: ``zero`` for an unknown mode."""
    if sampling_mode == CLOSEST:
        return _closest(id, uvw, src, extra)
    if sampling_mode == LINEAR:
        val, _grad = _trilinear(id, uvw, src, extra)
        return val
    return zero


@func
def _sample_grad(
    id: wp.uint64, uvw: wp.vec3, sampling_mode: int, grad: inout(Any), src: Any, extra: Any,
    zero: Any,
):  # fmt: skip
    """``volume_sample_grad``: the value, and its gradient written to ``grad`` (zero for
    ``CLOSEST`` and unknown modes)."""
    grad = _outer(zero, wp.vec3(0.0))
    if sampling_mode == CLOSEST:
        return _closest(id, uvw, src, extra)
    if sampling_mode == LINEAR:
        val, g = _trilinear(id, uvw, src, extra)
        grad = g  # noqa: F841 - in-out
        return val
    return zero


# -- the dtype-generic builtins' implementations (kdsl.frontend.builtins_volume) -------------


@func
def volume_sample_value(id: wp.uint64, uvw: wp.vec3, sampling_mode: int, like: Any):
    """``volume_sample(id, uvw, sampling_mode, dtype=type(like))``; ``like`` is a zero of
    the value type (zero is also the answer for a grid of another type)."""
    rec = wp.object_record(id, VolumeRecord)
    src = _typed_words(rec, like)
    if rec.grid_type != _grid_type_of(like):
        return like
    return _sample(id, uvw, sampling_mode, src, like, like)


@func
def volume_sample_grad_value(
    id: wp.uint64, uvw: wp.vec3, sampling_mode: int, grad: inout(Any), like: Any
):  # fmt: skip
    """``volume_sample_grad(id, uvw, sampling_mode, grad, dtype=type(like))``."""
    rec = wp.object_record(id, VolumeRecord)
    src = _typed_words(rec, like)
    if rec.grid_type != _grid_type_of(like):
        grad = _outer(like, wp.vec3(0.0))
        return like
    return _sample_grad(id, uvw, sampling_mode, grad, src, like, like)


@func
def volume_lookup_value(id: wp.uint64, i: int, j: int, k: int, like: Any):
    """``volume_lookup(id, i, j, k, dtype=type(like))``: voxel ``(i, j, k)``'s value (the
    tile value or background where no leaf holds it)."""
    rec = wp.object_record(id, VolumeRecord)
    src = _typed_words(rec, like)
    if rec.grid_type != _grid_type_of(like):
        return like
    return _read(rec, _locate(id, i, j, k), i, j, k, src, like)


@func
def volume_lookup_value(id: wp.uint64, ijk: wp.vec3i, like: Any):  # noqa: F811 - vec3i
    """``volume_lookup(id, ijk, dtype=type(like))``: voxel ``ijk``'s value."""
    return volume_lookup_value(id, ijk[0], ijk[1], ijk[2], like)


@func
def volume_store_value(id: wp.uint64, i: int, j: int, k: int, value: Any):
    """``volume_store(id, i, j, k, value)``: writes voxel ``(i, j, k)`` when a leaf holds
    it (tiles and the background are never written), and the grid's type is the value's."""
    rec = wp.object_record(id, VolumeRecord)
    src = _typed_words(rec, value)
    if rec.grid_type == _grid_type_of(value):
        loc = _locate(id, i, j, k)
        if loc[1] == LEAF:
            _store(src.words, _value_word(rec, loc, i, j, k), value)


@func
def volume_store_value(id: wp.uint64, ijk: wp.vec3i, value: Any):  # noqa: F811 - vec3i
    """``volume_store(id, ijk, value)``: ``volume_store_value`` at voxel ``ijk``."""
    volume_store_value(id, ijk[0], ijk[1], ijk[2], value)


@func
def volume_sample_index_value(
    id: wp.uint64, uvw: wp.vec3, sampling_mode: int, voxel_data: wp.array(dtype=Any),
    background: Any, zero: Any,
):  # fmt: skip
    """``volume_sample_index``; ``zero`` (a zero of the value type) for an unknown mode."""
    return _sample(id, uvw, sampling_mode, voxel_data, background, zero)


@func
def volume_sample_grad_index_value(
    id: wp.uint64, uvw: wp.vec3, sampling_mode: int, voxel_data: wp.array(dtype=Any),
    background: Any, grad: inout(Any), zero: Any,
):  # fmt: skip
    """``volume_sample_grad_index``; ``zero`` is a zero of the value type."""
    return _sample_grad(id, uvw, sampling_mode, grad, voxel_data, background, zero)


# -- typed builtins ------------------------------------------------------------------------


@func
def volume_sample_f(id: wp.uint64, uvw: wp.vec3, sampling_mode: int) -> float:
    """Sample the float32 volume ``id`` at index-space point ``uvw`` (``CLOSEST``:
    the nearest voxel; ``LINEAR``: trilinear); zero for a volume of another type."""
    return volume_sample_value(id, uvw, sampling_mode, wp.float32(0.0))


@func
def volume_sample_v(id: wp.uint64, uvw: wp.vec3, sampling_mode: int) -> wp.vec3:
    """Sample the vec3f volume ``id`` at index-space point ``uvw`` (see
    ``volume_sample_f``)."""
    return volume_sample_value(id, uvw, sampling_mode, wp.vec3(0.0))


@func
def volume_sample_i(id: wp.uint64, uvw: wp.vec3) -> int:
    """The int32 volume ``id``'s voxel nearest index-space point ``uvw`` (halfway
    rounds away from zero)."""
    return volume_sample_value(id, uvw, CLOSEST, wp.int32(0))


@func
def volume_sample_grad_f(
    id: wp.uint64, uvw: wp.vec3, sampling_mode: int, grad: inout(wp.vec3)
) -> float:  # fmt: skip
    """Sample the float32 volume ``id`` at ``uvw`` and write the sample's gradient with
    respect to ``uvw`` (index space) to ``grad`` (zero for ``CLOSEST``)."""
    return volume_sample_grad_value(id, uvw, sampling_mode, grad, wp.float32(0.0))


@func
def volume_lookup_f(id: wp.uint64, i: int, j: int, k: int) -> float:
    """The float32 value of voxel ``(i, j, k)`` of volume ``id`` (its tile's value or the
    background where no leaf holds it)."""
    return volume_lookup_value(id, i, j, k, wp.float32(0.0))


@func
def volume_lookup_v(id: wp.uint64, i: int, j: int, k: int) -> wp.vec3:
    """The vec3f value of voxel ``(i, j, k)`` of volume ``id``."""
    return volume_lookup_value(id, i, j, k, wp.vec3(0.0))


@func
def volume_lookup_i(id: wp.uint64, i: int, j: int, k: int) -> int:
    """The int32 value of voxel ``(i, j, k)`` of volume ``id``."""
    return volume_lookup_value(id, i, j, k, wp.int32(0))


@func
def volume_lookup_f(id: wp.uint64, ijk: wp.vec3i) -> float:  # noqa: F811 - vec3i
    """The float32 value of voxel ``ijk`` of volume ``id``."""
    return volume_lookup_value(id, ijk, wp.float32(0.0))


@func
def volume_lookup_v(id: wp.uint64, ijk: wp.vec3i) -> wp.vec3:  # noqa: F811 - vec3i
    """The vec3f value of voxel ``ijk`` of volume ``id``."""
    return volume_lookup_value(id, ijk, wp.vec3(0.0))


@func
def volume_lookup_i(id: wp.uint64, ijk: wp.vec3i) -> int:  # noqa: F811 - vec3i
    """The int32 value of voxel ``ijk`` of volume ``id``."""
    return volume_lookup_value(id, ijk, wp.int32(0))


@func
def volume_store_f(id: wp.uint64, i: int, j: int, k: int, value: float):
    """Write ``value`` to voxel ``(i, j, k)`` of the float32 volume ``id`` when a leaf holds
    it (no voxel is allocated or activated)."""
    volume_store_value(id, i, j, k, value)


@func
def volume_store_v(id: wp.uint64, i: int, j: int, k: int, value: wp.vec3):
    """Write ``value`` to voxel ``(i, j, k)`` of the vec3f volume ``id`` (see
    ``volume_store_f``)."""
    volume_store_value(id, i, j, k, value)


@func
def volume_store_i(id: wp.uint64, i: int, j: int, k: int, value: int):
    """Write ``value`` to voxel ``(i, j, k)`` of the int32 volume ``id`` (see
    ``volume_store_f``)."""
    volume_store_value(id, i, j, k, value)


@func
def volume_store_f(id: wp.uint64, ijk: wp.vec3i, value: float):  # noqa: F811 - vec3i
    """Write ``value`` to voxel ``ijk`` of the float32 volume ``id`` when a leaf holds it."""
    volume_store_value(id, ijk, value)


@func
def volume_store_v(id: wp.uint64, ijk: wp.vec3i, value: wp.vec3):  # noqa: F811 - vec3i
    """Write ``value`` to voxel ``ijk`` of the vec3f volume ``id``."""
    volume_store_value(id, ijk, value)


@func
def volume_store_i(id: wp.uint64, ijk: wp.vec3i, value: int):  # noqa: F811 - vec3i
    """Write ``value`` to voxel ``ijk`` of the int32 volume ``id``."""
    volume_store_value(id, ijk, value)


@func
def volume_lookup_index(id: wp.uint64, i: int, j: int, k: int) -> int:
    """The index of voxel ``(i, j, k)`` in a per-voxel array of volume ``id``
    (``volume_sample_index``'s ``voxel_data``), or -1 when it has none."""
    rec = wp.object_record(id, VolumeRecord)
    return int(_voxel_index(rec, _locate(id, i, j, k), i, j, k)) - 1


@func
def volume_lookup_index(id: wp.uint64, ijk: wp.vec3i) -> int:  # noqa: F811 - vec3i
    """The index of voxel ``ijk`` in a per-voxel array of volume ``id``, or -1."""
    return volume_lookup_index(id, ijk[0], ijk[1], ijk[2])


@func
def volume_voxel_count(id: wp.uint64) -> int:
    """The number of indexable voxels of volume ``id`` (the length a per-voxel array
    needs), at most ``2**31 - 1``."""
    return wp.object_record(id, VolumeRecord).voxel_count


# -- index and world space -------------------------------------------------------------------


@func
def _map(rec: VolumeRecord, like: wp.vec3):
    """The grid's float32 map: index-to-world matrix, its inverse, the translation."""
    return rec.matf, rec.invmatf, rec.vecf


@func
def _map(rec: VolumeRecord, like: wp.vec3d):
    """The grid's float64 map (the same three parts)."""
    return rec.matd, rec.invmatd, rec.vecd


def _define_maps(vec: Any) -> tuple:
    """The map builtins for points of type ``vec`` (vec3: float32, computed with the
    grid's float32 matrices; vec3d: float64)."""

    @func
    def volume_index_to_world(id: wp.uint64, uvw: vec) -> vec:
        """Index-space point ``uvw`` of volume ``id`` in world space."""
        mat, _inv, t = _map(wp.object_record(id, VolumeRecord), uvw)
        return mat * uvw + t

    @func
    def volume_world_to_index(id: wp.uint64, xyz: vec) -> vec:
        """World-space point ``xyz`` in volume ``id``'s index space."""
        _mat, inv, t = _map(wp.object_record(id, VolumeRecord), xyz)
        return inv * (xyz - t)

    @func
    def volume_index_to_world_dir(id: wp.uint64, uvw: vec) -> vec:
        """Index-space direction ``uvw`` of volume ``id`` in world space (no translation)."""
        return _map(wp.object_record(id, VolumeRecord), uvw)[0] * uvw

    @func
    def volume_world_to_index_dir(id: wp.uint64, xyz: vec) -> vec:
        """World-space direction ``xyz`` in volume ``id``'s index space (no translation)."""
        return _map(wp.object_record(id, VolumeRecord), xyz)[1] * xyz

    return (volume_index_to_world, volume_world_to_index, volume_index_to_world_dir,
            volume_world_to_index_dir)  # fmt: skip


for _vec in (wp.vec3, wp.vec3d):
    (volume_index_to_world, volume_world_to_index, volume_index_to_world_dir,
     volume_world_to_index_dir) = _define_maps(_vec)  # fmt: skip


# -- the seeds' older names -------------------------------------------------------------------


@func
def volume_sample_world(id: wp.uint64, xyz: wp.vec3, sampling_mode: int) -> float:
    """Older name: the float32 volume ``id`` sampled at world-space point ``xyz``."""
    return volume_sample_f(id, volume_world_to_index(id, xyz), sampling_mode)


@func
def volume_sample_local(id: wp.uint64, uvw: wp.vec3, sampling_mode: int) -> float:
    """Older name of ``volume_sample_f``."""
    return volume_sample_f(id, uvw, sampling_mode)


@func
def volume_transform(id: wp.uint64, uvw: wp.vec3) -> wp.vec3:
    """Older name of ``volume_index_to_world``."""
    return volume_index_to_world(id, uvw)


@func
def volume_transform_inv(id: wp.uint64, xyz: wp.vec3) -> wp.vec3:
    """Older name of ``volume_world_to_index``."""
    return volume_world_to_index(id, xyz)
