"""The NanoVDB format and the host side of ``kdsl.Volume``: layouts, builds, round trips
through files under every codec, grids exchanged with warp-lang both ways (skipped
without it), bad input, and a Hypothesis fuzz of the reader."""

from __future__ import annotations

import io
import struct
import sys
import zlib
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import kdsl as wp
from kdsl.errors import KdslTypeError
from kdsl.geometry.nanovdb import GridType, value_layout
from kdsl.geometry.nanovdb.errors import NanoVDBCodecError, NanoVDBError
from kdsl.geometry.nanovdb.layout import GRID_SIZE, LEAF_OFF_VALUE_MASK, TREE_SIZE
from kdsl.geometry.nanovdb.reader import read_grids
from kdsl.geometry.nanovdb.writer import name_key
from kdsl.geometry.volume_args import VolumeError

cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")
try:
    import blosc  # noqa: F401

    HAS_BLOSC = True
except ImportError:
    HAS_BLOSC = False
CODECS = [
    "none",
    "zip",
    pytest.param("blosc", marks=pytest.mark.skipif(not HAS_BLOSC, reason="needs blosc")),
]


@pytest.fixture(scope="module")
def warp():
    w = pytest.importorskip("warp")
    w.config.quiet = True
    return w


def _field(shape=(10, 9, 3), seed=0, vec=False):
    rng = np.random.default_rng(seed)
    return rng.standard_normal((*shape, 3) if vec else shape).astype(np.float32)


def _voxel_values(volume: wp.Volume) -> dict[tuple[int, int, int], object]:
    """Every active voxel's value, decoded from the leaves by the layout alone (no
    builder code): the test's own reader of NanoVDB leaves."""
    g = volume.info
    lay = g.layout
    out = {}
    for n in range(g.leaf_count):
        at = g.leaf_offset + n * lay.leaf_size
        origin = np.array(struct.unpack_from("<3i", g.data, at)) & ~7
        mask = np.unpackbits(
            np.frombuffer(g.data, np.uint8, 64, at + LEAF_OFF_VALUE_MASK), bitorder="little"
        )
        count = 512 * int(np.prod(lay.value_shape))
        vals = np.frombuffer(g.data, lay.value_dtype, count, at + lay.leaf_off_table)
        vals = vals.reshape(512, *lay.value_shape)
        for slot in np.flatnonzero(mask):
            key = tuple(int(c) for c in origin + [slot >> 6, (slot >> 3) & 7, slot & 7])
            out[key] = vals[slot].tolist()
    return out


# --- layout ---------------------------------------------------------------------------


def test_value_layouts_match_nanovdb():
    """A few sizes and offsets as PNanoVDB lists them."""
    f, v3, v3d, ix = (
        value_layout(t) for t in (GridType.FLOAT, GridType.VEC3F, GridType.VEC3D, GridType.ONINDEX)
    )
    assert (f.root_size, f.root_tile_size, f.upper_size, f.lower_size, f.leaf_size) == (
        64,
        32,
        270400,
        33856,
        2144,
    )
    assert (v3.table_stride, v3.upper_size, v3.leaf_off_table, v3.leaf_size) == (
        16,
        532544,
        128,
        6272,
    )
    assert (v3d.root_tile_off_value, v3d.root_tile_size, v3d.upper_off_table) == (24, 64, 8288)
    assert (ix.root_off_background, ix.leaf_size, ix.is_index) == (32, 96, True)
    assert value_layout(GridType.FP4) is None and value_layout(99) is None


def test_name_key_is_nanovdb_string_hash():
    assert name_key("") == 0
    assert name_key("a") == 97
    assert name_key("ab") == 97 * 67 + 98


# --- builds -----------------------------------------------------------------------------


def test_load_from_numpy_float_grid():
    a = _field()
    v = wp.Volume.load_from_numpy(a, min_world=(0.5, -1.0, 2.0), voxel_size=0.25, bg_value=-1.0)
    assert v.get_tiles().numpy().tolist() == [[0, 0, 0], [0, 8, 0], [8, 0, 0], [8, 8, 0]]
    assert v.get_voxel_count() == 2048 and v.get_tile_count() == 4
    assert tuple(v.get_active_stats()) == (2048, 4, 1, 1) and not v.is_rebuildable
    assert v.dtype is wp.float32 and not v.is_index
    assert v.get_voxel_size() == (0.25, 0.25, 0.25)
    info = v.get_grid_info()
    assert (info.type_str, info.grid_count, info.size_in_bytes) == ("float", 1, v.info.grid_size)
    assert list(info.translation) == [0.5, -1.0, 2.0]
    values = _voxel_values(v)
    assert len(values) == 2048 and values[(9, 8, 2)] == a[9, 8, 2] and values[(15, 15, 7)] == -1
    assert v.info.background == -1.0 and v.info.index_bbox == ((0, 0, 0), (15, 15, 7))
    assert v.info.world_bbox == ((0.5, -1.0, 2.0), (4.5, 3.0, 4.0))
    assert v.array().numpy().tobytes() == v.info.data


def test_grid_types_from_background():
    a = _field((4, 4, 4))
    assert wp.Volume.load_from_numpy(a.astype(np.int32), bg_value=3).dtype is wp.int32
    vv = wp.Volume.load_from_numpy(_field((4, 4, 4), vec=True), bg_value=(0.0, 1.0, 2.0))
    assert vv.dtype is wp.vec3f and _voxel_values(vv)[(7, 7, 7)] == [0.0, 1.0, 2.0]
    for bg, t in [
        (wp.vec3d(1, 2, 3), wp.vec3d),
        (np.float64(2), wp.float64),
        (np.uint32(1), wp.uint32),
        (np.int64(1), wp.int64),
        ([1, 2, 3, 4], wp.vec4f),
    ]:
        assert wp.Volume.allocate((0, 0, 0), (3, 3, 3), 0.5, bg_value=bg).dtype is t


def test_allocate_by_voxels_index_grid_and_features():
    pts = np.array([[0, 0, 0], [3, 4, 5], [3, 4, 5], [100, -20, 7], [-5000, 1, 1]], np.int32)
    v = wp.Volume.allocate_by_voxels(
        wp.array(pts, dtype=wp.vec3i), voxel_size=0.5, translation=(1, 2, 3)
    )
    assert v.is_index and v.dtype is None and v.get_voxel_count() == 4
    assert v.get_tiles().numpy().tolist() == [[-5000, 0, 0], [96, -24, 0], [0, 0, 0]]
    assert v.get_voxels().numpy().tolist() == [[-5000, 1, 1], [100, -20, 7], [0, 0, 0], [3, 4, 5]]
    assert v.info.index_count == 5  # index 0 is the background
    density = np.arange(5, dtype=np.float32) * 2
    f = wp.Volume.from_index_grid(v, {"density": density, "velocity": np.ones((5, 3))})
    assert f.get_feature_array_count() == 2
    assert f.feature_array(0).numpy().tolist() == density.tolist()
    assert f.feature_array(1).dtype is wp.vec3d and f.get_feature_array_info(1).type_str == "Vec3d"
    assert f.feature_array(0, dtype=wp.uint8).shape == (20,)
    back = wp.Volume.load_from_nvdb(_saved(f, "zip"))
    assert back.feature_array(0).numpy().tolist() == density.tolist()
    assert back.get_feature_array_info(0).name == "density"
    with pytest.raises(VolumeError, match="no feature array 2"):
        f.feature_array(2)
    with pytest.raises(VolumeError, match="values of 4 bytes"):
        f.feature_array(0, dtype=wp.float64)


def test_world_space_points_round_half_up():
    """Float points are world positions, rounded to the nearest voxel (halves up)."""
    pts = wp.array(np.array([[0.74, 0.76, -0.25]], np.float32), dtype=wp.vec3)
    v = wp.Volume.allocate_by_voxels(pts, voxel_size=0.5)
    assert v.get_voxels().numpy().tolist() == [[1, 2, 0]]
    t = wp.Volume.allocate_by_tiles(pts, voxel_size=0.01, bg_value=0.0, translation=(0, 0, 1))
    assert t.get_tiles().numpy().tolist() == [[72, 72, -128]]


def test_get_tiles_into_out():
    v = wp.Volume.allocate((0, 0, 0), (9, 0, 0), 1.0)
    out = wp.zeros(3, dtype=wp.vec3i)
    assert v.get_tiles(out) is out and out.numpy().tolist()[:2] == [[0, 0, 0], [8, 0, 0]]
    with pytest.raises(VolumeError, match="at least 2"):
        v.get_tiles(wp.zeros(1, dtype=wp.vec3i))


# --- files --------------------------------------------------------------------------------


def _unsummed(grid: bytes) -> bytes:
    """A grid's bytes but its checksum."""
    return grid[:8] + grid[16:]


def _saved(volume, codec="none") -> bytes:
    f = io.BytesIO()
    volume.save_to_nvdb(f, codec=codec)
    return f.getvalue()


@pytest.mark.parametrize("codec", CODECS)
def test_round_trip_through_files(codec, tmp_path):
    vols = [
        wp.Volume.load_from_numpy(_field(), (1, 2, 3), 0.5, -2.0),
        wp.Volume.load_from_numpy(_field(vec=True), bg_value=[0, 0, 0]),
        wp.Volume.allocate_by_voxels(
            wp.array(np.array([[5, 6, 7]], np.int32), dtype=wp.vec3i), voxel_size=2.0
        ),
    ]
    for v in vols:
        path = tmp_path / f"v.{codec}.nvdb"
        assert v.save_to_nvdb(path, codec=codec) == path
        back = wp.Volume.load_from_nvdb(str(path))
        assert _unsummed(back.info.data) == _unsummed(v.info.data)
        assert back.info.checksum >> 32 != 0xFFFFFFFF  # files get a full checksum
        assert v.info.checksum == (1 << 64) - 1  # in memory: disabled, as in Warp
        assert back.get_voxels().numpy().tolist() == v.get_voxels().numpy().tolist()
        with open(path, "rb") as f:
            assert wp.Volume.load_from_nvdb(f).info.data == back.info.data


def test_raw_buffers_and_multi_grid_files():
    a, b = wp.Volume.load_from_numpy(_field()), wp.Volume.allocate((0, 0, 0), (20, 1, 1), 0.1)
    assert wp.Volume(a.array()).info.data == a.info.data
    from kdsl.geometry.nanovdb.writer import write_nvdb

    both = wp.Volume.load_from_nvdb(write_nvdb([a.info, b.info]))
    nxt = both.load_next_grid()
    assert (both.info.data, nxt.info.data) == (a.info.data, b.info.data)
    assert nxt.load_next_grid() is None


# --- against warp-lang ----------------------------------------------------------------------

_WARP_KERNELS = {}


def _warp_kernels(warp):
    """Warp kernels that look voxels up and sample world points (made once)."""
    if not _WARP_KERNELS:

        @warp.kernel
        def lookup(vol: warp.uint64, ijk: warp.array(dtype=warp.vec3i), out: warp.array(dtype=Any)):
            i = warp.tid()  # one kernel for every value type: Warp's generic volume_lookup
            p = ijk[i]
            out[i] = warp.volume_lookup(vol, p[0], p[1], p[2], dtype=out.dtype)

        @warp.kernel
        def lookup_index(
            vol: warp.uint64, ijk: warp.array(dtype=warp.vec3i), out: warp.array(dtype=warp.int64)
        ):
            p = ijk[warp.tid()]
            out[warp.tid()] = warp.int64(warp.volume_lookup_index(vol, p[0], p[1], p[2]))

        @warp.kernel
        def sample(vol: warp.uint64, xs: warp.array(dtype=warp.vec3), out: warp.array(dtype=float)):
            i = warp.tid()
            q = warp.volume_world_to_index(vol, xs[i])
            out[i] = warp.volume_sample_f(vol, q, warp.Volume.LINEAR)

        _WARP_KERNELS.update(lookup=lookup, sample=sample, lookup_index=lookup_index)
    return _WARP_KERNELS


def _warp_run(warp, kernel, vol, points, dtype, out_dtype=float):
    pts = warp.array(points, dtype=dtype, device="cpu")
    out = warp.zeros(len(points), dtype=out_dtype, device="cpu")
    warp.launch(
        _warp_kernels(warp)[kernel],
        dim=len(points),
        inputs=[warp.uint64(vol.id), pts, out],
        device="cpu",
    )
    return out.numpy()


@pytest.mark.parametrize("codec", CODECS)
def test_kdsl_files_load_and_sample_in_warp(warp, codec, tmp_path):
    a = _field((13, 9, 5), seed=1)
    ours = wp.Volume.load_from_numpy(a, (0.5, -1.0, 2.0), 0.25, -1.0)
    path = str(tmp_path / "k.nvdb")
    ours.save_to_nvdb(path, codec=codec)
    with open(path, "rb") as f:  # Warp reads file objects and buffers, not paths
        theirs = warp.Volume.load_from_nvdb(f, device="cpu")
    ref = warp.Volume.load_from_numpy(a, (0.5, -1.0, 2.0), 0.25, -1.0, device="cpu")
    for getter in ("get_tiles", "get_voxels"):
        assert (
            getattr(theirs, getter)().numpy().tolist() == getattr(ours, getter)().numpy().tolist()
        )
        assert getattr(ref, getter)().numpy().tolist() == getattr(ours, getter)().numpy().tolist()
    ijk = np.stack(np.meshgrid(*(np.arange(-2, 18),) * 3, indexing="ij"), -1).reshape(-1, 3)
    looked = _warp_run(warp, "lookup", theirs, ijk.astype(np.int32), warp.vec3i)
    assert np.array_equal(looked, _warp_run(warp, "lookup", ref, ijk.astype(np.int32), warp.vec3i))
    xs = np.random.default_rng(2).uniform(-1, 5, (500, 3)).astype(np.float32)
    assert np.array_equal(
        _warp_run(warp, "sample", theirs, xs, warp.vec3),
        _warp_run(warp, "sample", ref, xs, warp.vec3),
    )
    assert theirs.get_grid_info().type_str == "float"
    assert np.allclose(
        np.array(theirs.get_grid_info().transform_matrix).reshape(3, 3), np.eye(3) * 0.25
    )


def test_warp_bytes_load_in_kdsl(warp, tmp_path):
    a = _field((13, 9, 5), seed=3)
    theirs = warp.Volume.load_from_numpy(a, (0.5, -1.0, 2.0), 0.25, -1.0, device="cpu")
    ours = wp.Volume.load_from_numpy(a, (0.5, -1.0, 2.0), 0.25, -1.0)
    loaded = [wp.Volume.load_from_nvdb(theirs.array().numpy().tobytes())]
    for codec in ["none", "zip"] + (["blosc"] if HAS_BLOSC else []):
        path = str(tmp_path / f"w_{codec}.nvdb")
        theirs.save_to_nvdb(path, codec=codec)  # Warp's writer, its file sizes and all
        loaded.append(wp.Volume.load_from_nvdb(path))
    for v in loaded:
        assert v.get_tiles().numpy().tolist() == ours.get_tiles().numpy().tolist()
        assert _voxel_values(v) == _voxel_values(ours)
        assert v.get_grid_info()[2:] == ours.get_grid_info()[2:]
        assert np.array_equal(v.info.index_to_world, ours.info.index_to_world)
        assert np.array_equal(v.info.world_to_index, ours.info.world_to_index)


def test_allocations_match_warp(warp):
    rng = np.random.default_rng(4)
    ipts = rng.integers(-300, 300, (200, 3)).astype(np.int32)
    fpts = rng.uniform(-3, 3, (200, 3)).astype(np.float32)
    cases = [
        (lambda m, d: m.Volume.allocate((-9, 0, 3), (20, 17, 9), 0.5, 1.0, (1, 2, 3), device=d)),
        (
            lambda m, d: m.Volume.allocate(
                (-1.0, 0, 0.2),
                (2.0, 1.0, 1.0),
                0.1,
                0.0,
                (0.5, 0, 0),
                points_in_world_space=True,
                device=d,
            )
        ),
        (
            lambda m, d: m.Volume.allocate_by_tiles(
                m.array(ipts, dtype=m.vec3i, device=d), 0.1, 2.5, device=d
            )
        ),
        (
            lambda m, d: m.Volume.allocate_by_tiles(
                m.array(fpts, dtype=m.vec3, device=d), 0.05, None, (0.1, 0.2, 0.3), device=d
            )
        ),
        (
            lambda m, d: m.Volume.allocate_by_voxels(
                m.array(ipts, dtype=m.vec3i, device=d), 0.1, device=d
            )
        ),
        (
            lambda m, d: m.Volume.allocate_by_voxels(
                m.array(fpts, dtype=m.vec3, device=d), 0.07, (0.1, 0.2, 0.3), device=d
            )
        ),
    ]
    for make in cases:
        ours, theirs = make(wp, "cpu"), make(warp, "cpu")
        assert ours.get_tiles().numpy().tolist() == theirs.get_tiles().numpy().tolist()
        assert ours.get_voxels().numpy().tolist() == theirs.get_voxels().numpy().tolist()
        assert ours.get_grid_info().type_str == theirs.get_grid_info().type_str
        assert ours.get_voxel_size() == theirs.get_voxel_size()
    # Warp reads kdsl's index grids with the same indices as its own
    ours, theirs = cases[4](wp, "cpu"), cases[4](warp, "cpu")
    ijk = np.concatenate([ipts, ipts + 1])
    mine = warp.Volume.load_from_nvdb(_saved(ours), device="cpu")
    assert np.array_equal(
        _warp_run(warp, "lookup_index", mine, ijk, warp.vec3i, warp.int64),
        _warp_run(warp, "lookup_index", theirs, ijk, warp.vec3i, warp.int64),
    )


# --- bad input ----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def small_file() -> bytes:
    return _saved(wp.Volume.load_from_numpy(_field((4, 4, 4)), bg_value=0.0))


def _patch(data: bytes, offset: int, fmt: str, *values) -> bytes:
    out = bytearray(data)
    struct.pack_into(fmt, out, offset, *values)
    return bytes(out)


_GRID = 16 + 176 + 1  # file header, metadata, the empty name's NUL


@pytest.mark.parametrize(
    ("mutate", "match"),
    [
        (lambda d: d[:10], "truncated"),
        (lambda d: d[: _GRID + 100], "truncated"),
        (lambda d: d[:-32], "truncated"),
        (lambda d: b"OpenVDB!" + d[8:], "wrong magic"),
        (lambda d: _patch(d, 8, "<I", 31 << 21), "unsupported NanoVDB version 31"),
        (lambda d: _patch(d, _GRID + 16, "<I", 33 << 21), "unsupported NanoVDB version 33"),
        (lambda d: _patch(d, _GRID + 636, "<I", GridType.FP4), "unsupported grid type FP4"),
        (lambda d: _patch(d, _GRID + 636, "<I", 77), "unsupported grid type unknown"),
        (lambda d: _patch(d, len(d) - 8, "<f", 1.5), "bad checksum"),
        (lambda d: _patch(d, 14, "<H", 7), "unsupported codec 7"),
        (lambda d: _patch(d, _GRID + 40, "256s", b"x" * 256), "not NUL-terminated"),
        (lambda d: _patch(d, 16 + 136, "<I", 1 << 30), "grid name of"),
        (lambda d: _patch(d, 16, "<Q", 1 << 40), "truncated"),
        (lambda d: _patch(d, _GRID + 20, "<I", 2), "not stored breadth-first"),
        (lambda d: d + b"\0" * 8, "truncated"),
    ],
)
def test_corrupt_files_raise_clear_errors(small_file, mutate, match):
    with pytest.raises(NanoVDBError, match=match) as err:
        read_grids(mutate(small_file))
    assert "<bytes>" in str(err.value)


def test_structural_corruption_is_caught_without_checksum(small_file):
    """With the checksum disabled, each structural fault is still found."""
    d = _patch(small_file, _GRID + 8, "<Q", (1 << 64) - 1)
    assert read_grids(d)[0].leaf_count == 1
    tree = _GRID + GRID_SIZE
    root = tree + TREE_SIZE
    for offset, fmt, value, match in [
        (tree + 40, "<I", 100000, "upper nodes .* overrun"),
        (tree + 16, "<q", 70, "misaligned"),
        (root + 64 + 8, "<q", 96 + 32, "root tile's child offset"),
        (root + 24, "<I", 1 << 28, "root tiles overrun"),
        (_GRID + 640, "<q", 800, "overlaps the blind data"),
        (_GRID + 296 + 88, "<d", float("nan"), "not finite"),
    ]:
        with pytest.raises(NanoVDBError, match=match):
            read_grids(_patch(d, offset, fmt, value))
    # a root with no tiles leaves its nodes unreachable, which is no fault (fuzz regression)
    assert read_grids(_patch(d, root + 24, "<I", 0))[0].root_tile_count == 0


def test_file_and_argument_errors(tmp_path, monkeypatch, small_file):
    with pytest.raises(NanoVDBError, match=r"no_such\.nvdb: cannot read"):
        wp.Volume.load_from_nvdb(str(tmp_path / "no_such.nvdb"))
    path = tmp_path / "bad.nvdb"
    path.write_bytes(small_file[:100])
    with pytest.raises(NanoVDBError, match=r"bad\.nvdb: truncated"):
        wp.Volume.load_from_nvdb(path)
    with pytest.raises(NanoVDBError, match="bytes-like"):
        wp.Volume.load_from_nvdb(3.5)
    with pytest.raises(NanoVDBError, match="empty"):
        wp.Volume.load_from_nvdb(b"")
    with pytest.raises(NanoVDBCodecError, match="unsupported NanoVDB codec 'lz4'"):
        wp.Volume.load_from_numpy(_field((2, 2, 2))).save_to_nvdb(io.BytesIO(), codec="lz4")
    monkeypatch.setitem(sys.modules, "blosc", None)  # as if not installed
    with pytest.raises(NanoVDBCodecError, match=r"kdsl\[volume\]"):
        wp.Volume.load_from_numpy(_field((2, 2, 2))).save_to_nvdb(io.BytesIO(), codec="blosc")
    blosc_file = _patch(small_file, 14, "<H", 2)
    with pytest.raises(NanoVDBCodecError, match="needs the 'blosc' package"):
        read_grids(blosc_file)


def test_corrupt_zip_data(small_file):
    grid = small_file[_GRID:]
    header = _patch(small_file[:_GRID], 14, "<H", 1)
    packed = zlib.compress(grid)
    good = header + struct.pack("<q", len(packed)) + packed
    assert read_grids(good)[0].data == grid
    for bad, match in [
        (header + struct.pack("<q", len(packed) + 9) + packed, "compressed chunk"),
        (
            header + struct.pack("<q", len(packed)) + packed[:20] + b"\0" * (len(packed) - 20),
            "corrupt ZIP",
        ),
        (header + struct.pack("<q", 11) + zlib.compress(b"tiny"), "does not inflate"),
    ]:
        with pytest.raises(NanoVDBError, match=match):
            read_grids(bad)


def test_volume_argument_errors():
    a = _field((4, 4, 4))
    with pytest.raises(VolumeError, match="positive and finite"):
        wp.Volume.load_from_numpy(a, voxel_size=0.0)
    with pytest.raises(VolumeError, match="non-empty 3-d"):
        wp.Volume.load_from_numpy(a[0])
    with pytest.raises(VolumeError, match=r"\(X, Y, Z, 3\)"):
        wp.Volume.load_from_numpy(a, bg_value=(0, 0, 0))
    with pytest.raises(KdslTypeError, match="no supported grid type"):
        wp.Volume.allocate((0, 0, 0), (1, 1, 1), 1.0, bg_value="x")
    with pytest.raises(KdslTypeError, match="bool"):
        wp.Volume.allocate((0, 0, 0), (1, 1, 1), 1.0, bg_value=True)
    with pytest.raises(VolumeError, match="no tiles"):
        wp.Volume.allocate((9, 0, 0), (0, 0, 0), 1.0)
    pts = wp.array(np.zeros((1, 3), np.int32), dtype=wp.vec3i)
    with pytest.raises(VolumeError, match="not both"):
        wp.Volume.allocate_by_voxels(pts, 1.0, transform=np.eye(3))
    with pytest.raises(VolumeError, match="singular"):
        wp.Volume.allocate_by_voxels(pts, transform=np.zeros((3, 3)))
    with pytest.raises(VolumeError, match="rebuildable"):
        wp.Volume.allocate_by_tiles(pts, 1.0, rebuildable=True)
    with pytest.raises(KdslTypeError, match="vec3i/vec3f"):
        wp.Volume.allocate_by_voxels(wp.array(np.zeros(3, np.float64)), 1.0)
    with pytest.raises(KdslTypeError, match="uint8"):
        wp.Volume(wp.array(np.zeros(4, np.float32)))


# --- fuzz -----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def fuzz_inputs(small_file):
    """A checksummed file, the same without its checksum (so mutations reach the
    structure checks), a raw index grid, and a ZIP-compressed file."""
    no_sum = _patch(small_file, _GRID + 8, "<Q", (1 << 64) - 1)
    pts = wp.array(np.array([[1, 2, 3], [40, 0, -9]], np.int32), dtype=wp.vec3i)
    index = wp.Volume.allocate_by_voxels(pts, 1.0).info.data
    zipped = _saved(wp.Volume.load_from_numpy(_field((4, 4, 4))), "zip")
    return [small_file, no_sum, _patch(index, 8, "<Q", (1 << 64) - 1), zipped]


@settings(
    max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    which=st.integers(0, 3),
    edits=st.lists(st.tuples(st.integers(0, 1 << 30), st.integers(0, 255)), min_size=1, max_size=6),
    head=st.booleans(),
    cut=st.integers(0, 1 << 30),
)
def test_fuzz_reader(fuzz_inputs, which, edits, head, cut):
    """Mutated bytes of valid files: a NanoVDBError or grids whose leaves read back,
    never another exception, a crash or a hang."""
    data = bytearray(fuzz_inputs[which])
    span = min(1200, len(data)) if head else len(data)  # most structure is in the head
    for pos, byte in edits:
        data[pos % span] = byte
    if cut % 4 == 0:
        data = data[: cut % len(data)]
    try:
        v = wp.Volume.load_from_nvdb(bytes(data), device="cpu")
    except NanoVDBError:
        return
    while v is not None:
        assert len(v.get_voxels().numpy()) <= 512 * v.get_tile_count()
        assert len(v.get_tiles().numpy()) == v.get_tile_count()
        v = v.load_next_grid()


# --- devices ----------------------------------------------------------------------------------


@cuda
def test_volume_on_cuda(small_file):
    v = wp.Volume.load_from_nvdb(small_file, device="cuda:0")
    assert v.device.is_cuda and v.array().device.is_cuda
    assert v.array().numpy().tobytes() == v.info.data
    assert v.get_tiles().device.is_cuda
    assert v.get_voxels().numpy().shape == (512, 3)
    back = wp.Volume.load_from_nvdb(_saved(v))
    assert _unsummed(back.info.data) == _unsummed(v.info.data)


# --- files made by NanoVDB itself (tests/geometry/data/nanovdb_fixtures.cpp) ----------------

DATA = __import__("pathlib").Path(__file__).parent / "data"


def _nanovdb_voxels(name: str) -> dict[tuple[int, int, int], list[float]]:
    """The active voxels NanoVDB's own iteration printed when it wrote the fixture."""
    rows = [line.split() for line in (DATA / f"nanovdb_{name}.txt").read_text().splitlines()]
    return {tuple(int(c) for c in r[:3]): [float(x) for x in r[3:]] for r in rows}


@pytest.mark.parametrize("codec", CODECS[1:])
def test_reads_nanovdb_level_set(codec):
    v = wp.Volume.load_from_nvdb(DATA / f"nanovdb_sphere_{codec}.nvdb")
    assert (v.get_grid_info().name, v.info.grid_class.name, v.dtype) == (
        "sphere",
        "LEVEL_SET",
        wp.float32,
    )
    expected = _nanovdb_voxels("sphere")
    values = _voxel_values(v)
    assert list(values) == list(expected)  # the active voxels, in NanoVDB's order
    # get_voxels lists every leaf voxel, active or not, as Warp's does
    assert v.get_voxel_count() == 512 * v.get_tile_count() == len(v.get_voxels().numpy())
    assert set(expected) <= {tuple(c) for c in v.get_voxels().numpy().tolist()}
    assert all(np.float32(values[k]) == np.float32(e[0]) for k, e in expected.items())
    assert v.get_voxel_size() == (0.5, 0.5, 0.5)
    assert list(v.get_grid_info().translation) == [0.25, 0.0, 0.0]


def test_reads_nanovdb_two_grids_and_index_grid():
    first = wp.Volume.load_from_nvdb(DATA / "nanovdb_two_grids.nvdb")
    second = first.load_next_grid()
    assert (first.get_grid_info().name, first.dtype) == ("velocity", wp.vec3f)
    assert (second.get_grid_info().name, second.dtype) == ("labels", wp.int32)
    assert second.info.background == -7
    expected = _nanovdb_voxels("two_grids")
    both = {**_voxel_values(first), **_voxel_values(second)}
    assert both == {k: (v if len(v) == 3 else int(v[0])) for k, v in expected.items()}
    index = wp.Volume.load_from_nvdb(DATA / "nanovdb_onindex.nvdb")
    assert index.is_index and index.get_feature_array_info(0).type_str == "float"
    indices = _nanovdb_voxels("onindex")
    sphere = _nanovdb_voxels("sphere")
    assert [tuple(c) for c in index.get_voxels().numpy().tolist()] == list(indices)
    channel = index.feature_array(0).numpy()
    assert all(channel[int(i[0])] == np.float32(sphere[k][0]) for k, i in indices.items())


# --- kernels read the loaded grids (the sampling itself is test_volume_sampling's) -----------


@wp.kernel
def _lookup_f(vol: wp.uint64, ijk: wp.array(dtype=wp.vec3i), out: wp.array(dtype=float)):
    i = wp.tid()
    p = ijk[i]
    out[i] = wp.volume_lookup_f(vol, p[0], p[1], p[2])


def _lookup(volume, coords, backend, device="cpu"):
    out = wp.zeros(len(coords), dtype=float, device=device)
    pts = wp.array(np.asarray(coords, np.int32), dtype=wp.vec3i, device=device)
    wp.launch(
        _lookup_f, dim=len(coords), inputs=[volume.id, pts, out], backend=backend, device=device
    )
    return out.numpy()


@pytest.mark.parametrize("backend", ["interp", "cpu"])
def test_kernels_read_loaded_grids(backend):
    """A NanoVDB-written level set and a kdsl-built grid, looked up by kernels."""
    sphere = _nanovdb_voxels("sphere")
    coords = list(sphere)[:: 40 if backend == "interp" else 1]
    v = wp.Volume.load_from_nvdb(DATA / "nanovdb_sphere_zip.nvdb")
    expected = np.array([sphere[c][0] for c in coords], np.float32)
    assert np.array_equal(_lookup(v, coords, backend), expected)
    a = _field((9, 9, 9), seed=5)
    built = wp.Volume.load_from_numpy(a, bg_value=-3.0)
    ijk = [(0, 0, 0), (8, 7, 6), (3, 1, 4), (20, 0, 0), (-1, 0, 0)]
    assert _lookup(built, ijk, backend).tolist() == [a[0, 0, 0], a[8, 7, 6], a[3, 1, 4], -3, -3]


@cuda
def test_kernels_read_loaded_grids_on_cuda():
    sphere = _nanovdb_voxels("sphere")
    v = wp.Volume.load_from_nvdb(
        DATA / "nanovdb_sphere_blosc.nvdb" if HAS_BLOSC else DATA / "nanovdb_sphere_zip.nvdb",
        device="cuda:0",
    )
    expected = np.array([e[0] for e in sphere.values()], np.float32)
    assert np.array_equal(_lookup(v, list(sphere), "cuda", "cuda:0"), expected)


def test_more_argument_errors(tmp_path):
    pts = wp.array(np.zeros((1, 3), np.int32), dtype=wp.vec3i)
    index = wp.Volume.allocate_by_voxels(pts, 1.0)
    dense = wp.Volume.load_from_numpy(_field((2, 2, 2)))
    with pytest.raises(VolumeError, match="needs an index volume"):
        wp.Volume.from_index_grid(dense, {})
    with pytest.raises(VolumeError, match="grid indexes 2"):
        wp.Volume.from_index_grid(index, {"x": np.zeros(3, np.float32)})
    with pytest.raises(KdslTypeError, match="feature arrays hold"):
        wp.Volume.from_index_grid(index, {"x": np.zeros(2, np.int8)})
    text = tmp_path / "t.nvdb"
    text.write_bytes(b"x")
    with open(text) as f, pytest.raises(NanoVDBError, match="binary mode"):
        wp.Volume.load_from_nvdb(f)
    far = wp.array(np.array([[3e9, 0, 0]], np.float32), dtype=wp.vec3)
    with pytest.raises(VolumeError, match="int32 index space"):
        wp.Volume.allocate_by_voxels(far, 1.0)
    with pytest.raises(VolumeError, match="more than 2\\*\\*24"):
        wp.Volume.allocate((0, 0, 0), (1 << 12, 1 << 12, 1 << 12), 1.0)
    with pytest.raises(KdslTypeError, match="voxel_size must be a number"):
        wp.Volume.load_from_numpy(_field((2, 2, 2)), voxel_size="big")
    with pytest.raises(VolumeError, match="min_world must be finite"):
        wp.Volume.load_from_numpy(_field((2, 2, 2)), min_world=(0, float("inf"), 0))
    with pytest.raises(VolumeError, match="a voxel_size or a transform"):
        wp.Volume.allocate_by_tiles(pts)
    with pytest.raises(VolumeError, match="on cpu"):
        dense.get_voxels(np.zeros((8, 3), np.int32))


@wp.kernel
def _store_f(vol: wp.uint64, ijk: wp.array(dtype=wp.vec3i), values: wp.array(dtype=float)):
    i = wp.tid()
    p = ijk[i]
    wp.volume_store_f(vol, p[0], p[1], p[2], values[i])


def test_saved_files_hold_what_kernels_stored():
    """save_to_nvdb writes the grid as kernels left it, with a checksum of that."""
    v = wp.Volume.allocate((0, 0, 0), (15, 7, 7), 0.5, bg_value=0.0)
    ijk = np.array([[0, 0, 0], [15, 7, 7], [9, 2, 3]], np.int32)
    wp.launch(
        _store_f,
        dim=3,
        inputs=[v.id, wp.array(ijk, dtype=wp.vec3i), wp.array([1.5, -2.0, 7.0], dtype=float)],
    )
    back = wp.Volume.load_from_nvdb(_saved(v, "zip"))
    values = _voxel_values(back)
    assert (values[(0, 0, 0)], values[(15, 7, 7)], values[(9, 2, 3)], values[(1, 1, 1)]) == (
        1.5,
        -2.0,
        7.0,
        0.0,
    )


def test_vec3_and_int_files_look_up_the_same_in_warp(warp):
    ijk = np.stack(np.meshgrid(*(np.arange(-1, 11),) * 3, indexing="ij"), -1).reshape(-1, 3)
    ijk = ijk.astype(np.int32)
    vec = _field((9, 10, 3), seed=6, vec=True)
    ints = np.random.default_rng(7).integers(-100, 100, (9, 10, 3)).astype(np.int32)
    for a, bg, out in [(vec, (1.0, 2.0, 3.0), warp.vec3), (ints, -5, warp.int32)]:
        ours = warp.Volume.load_from_nvdb(
            _saved(wp.Volume.load_from_numpy(a, bg_value=bg)), device="cpu"
        )
        theirs = warp.Volume.load_from_numpy(a, bg_value=bg, device="cpu")
        assert np.array_equal(
            _warp_run(warp, "lookup", ours, ijk, warp.vec3i, out),
            _warp_run(warp, "lookup", theirs, ijk, warp.vec3i, out),
        )


def test_reads_warps_rocks_asset_with_its_32_6_checksum(warp):
    """Warp's example asset: a NanoVDB 32.6 level set whose half checksum covers the
    head up to the first upper node (the pre-32.7 rule)."""
    import os

    path = os.path.join(os.path.dirname(warp.__file__), "examples", "assets", "rocks.nvdb")
    if not os.path.exists(path):
        pytest.skip("warp-lang ships no rocks.nvdb")
    with open(path, "rb") as f:
        data = f.read()
    v = wp.Volume.load_from_nvdb(data)
    assert (v.info.version >> 10, v.get_grid_info().name, v.dtype) == (
        (32 << 11) | 6,
        "surface",
        wp.float32,
    )
    assert v.info.checksum >> 32 == 0xFFFFFFFF  # a half checksum: the head only
    theirs = warp.Volume.load_from_nvdb(data, device="cpu")
    assert v.get_voxel_count() == theirs.get_voxel_count() == 512 * v.get_tile_count()
    assert v.get_tiles().numpy().tolist() == theirs.get_tiles().numpy().tolist()
    assert v.get_voxels().numpy().tolist() == theirs.get_voxels().numpy().tolist()
    assert v.get_active_stats().voxel_count == theirs.get_active_stats().voxel_count
    # the file is ZIP-compressed: change a byte of the head (its world bbox) and repack
    start = 16 + 176 + struct.unpack_from("<I", data, 16 + 136)[0]
    (size,) = struct.unpack_from("<q", data, start)
    grid = _patch(zlib.decompress(data[start + 8 : start + 8 + size]), 600, "<d", 123.0)
    packed = zlib.compress(grid)
    with pytest.raises(NanoVDBError, match="bad checksum"):
        read_grids(data[:start] + struct.pack("<q", len(packed)) + packed)


@pytest.fixture(scope="module")
def unsummed_grids():
    """Raw grids with their checksums disabled: a float grid, an OnIndex grid and one
    with a feature array, so each structural fault is what the reader reports."""
    pts = wp.array(np.array([[1, 2, 3], [9, 0, 0]], np.int32), dtype=wp.vec3i)
    index = wp.Volume.allocate_by_voxels(pts, 1.0)
    feature = wp.Volume.from_index_grid(index, {"f": np.zeros(3, np.float32)})
    dense = wp.Volume.load_from_numpy(_field((4, 4, 4)))
    return {"dense": dense.info, "index": index.info, "feature": feature.info}


@pytest.mark.parametrize(
    ("grid", "field", "fmt", "value", "match"),
    [
        ("dense", 24, "<I", 5, "grid index 5 of a count of 1"),
        ("dense", 632, "<I", 99, "unknown grid class 99"),
        ("dense", GRID_SIZE + 8, "<q", 64 + 64 + 32, "overlap or are out of order"),
        ("index", "leaf+80", "<Q", 7, "beyond the grid's 3"),
        ("index", "leaf+88", "<Q", 1, "prefix sums disagree"),
        ("dense", "upper_child", "<q", 8, "upper node's child offset"),
        ("dense", "lower_child", "<q", -64, "lower node's child offset"),
        ("feature", 648, "<I", 1 << 20, "blind data records at byte"),
        ("feature", "blind+0", "<q", 1 << 40, "lies outside the grid"),
        ("feature", "blind+32", "256s", b"n" * 256, "blind data 0 is not NUL"),
    ],
)
def test_structural_faults_in_raw_grids(unsummed_grids, grid, field, fmt, value, match):
    info = unsummed_grids[grid]
    lay = info.layout
    where = {
        "leaf+80": info.leaf_offset + 80,
        "leaf+88": info.leaf_offset + 88,
        "upper_child": info.upper_offset + lay.upper_off_table,
        "lower_child": info.lower_offset + lay.lower_off_table,
        "blind+0": info.blind_metadata_offset,
        "blind+32": info.blind_metadata_offset + 32,
    }.get(field, field)
    with pytest.raises(NanoVDBError, match=match):
        read_grids(_patch(info.data, where, fmt, value))


def test_file_segment_faults(small_file, tmp_path):
    meta = small_file[16 : 16 + 176]
    for bad, match in [
        (_patch(small_file, 12, "<H", 0), "holds no grid"),
        (small_file[:100], "truncated: grid metadata"),
        (small_file[:16] + _patch(meta, 0, "<Q", 5) + small_file[192:], "has a size of 5"),
        (_patch(small_file, 14, "<H", 1)[:_GRID] + b"\0\0", "before its chunk size"),
    ]:
        with pytest.raises(NanoVDBError, match=match):
            read_grids(bad)
    with pytest.raises(NanoVDBCodecError, match="unsupported NanoVDB codec 9"):
        wp.Volume.load_from_numpy(_field((2, 2, 2))).save_to_nvdb(io.BytesIO(), codec=9)
    with pytest.raises(NanoVDBError, match="cannot write NanoVDB file"):
        wp.Volume.load_from_numpy(_field((2, 2, 2))).save_to_nvdb(tmp_path / "no" / "f.nvdb")
