"""The vec3i voxel forms of the volume lookups and stores (the seeds'
``volume_lookup(vol, ijk)``): ``volume_lookup(id, ijk, dtype=...)``,
``volume_lookup_f/_v/_i/_index(id, ijk)``, ``volume_store(id, ijk, value)`` and
``volume_store_f/_v/_i(id, ijk, value)`` give exactly what the ``(i, j, k)`` forms give
(and the dense NumPy reference), on every backend; Warp 1.19 has only the ``(i, j, k)``
forms, so the Warp comparison reads the same bytes through those. Bad voxel arguments
are compile-time errors at the call."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from volume_reference import TILE, GridHandle, sparse_float_grid, typed_grid

import kdsl as wp
from kdsl.errors import KdslTypeError
from kdsl.geometry.nanovdb.layout import GridType
from tests.source_kernels import kernel_from_file

cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")
BACKENDS = [("interp", "cpu"), ("cpu", "cpu"), pytest.param("cuda", "cuda:0", marks=cuda)]


def voxels(dense, rng: np.random.Generator, n: int = 300) -> np.ndarray:
    """Voxels in and around the dense box (leaves, the tile, the background)."""
    lo = dense.lo - 4
    hi = dense.lo + np.array(dense.values.shape[:3]) + 4
    return rng.integers(lo, hi, (n, 3)).astype(np.int32)


@wp.kernel
def lookup_float(vid: wp.uint64, ijk: wp.array(dtype=wp.vec3i), out: wp.array2d(dtype=float)):
    t = wp.tid()
    v = ijk[t]
    out[t, 0] = wp.volume_lookup(vid, v)
    out[t, 1] = wp.volume_lookup(vid, v, dtype=float)
    out[t, 2] = wp.volume_lookup_f(vid, v)
    out[t, 3] = wp.volume_lookup_f(vid, v[0], v[1], v[2])
    out[t, 4] = wp.volume_lookup(vid, v[0], v[1], v[2], dtype=float)
    out[t, 5] = wp.volume_lookup(vid, wp.vec3i(v[0], v[1], v[2]))


@pytest.mark.parametrize("backend,device", BACKENDS)
def test_float_lookups_by_vec3i_equal_the_ijk_forms(backend, device):
    data, dense = sparse_float_grid(np.random.default_rng(7))
    grid = GridHandle(data, device, tiles=TILE)
    ijk = voxels(dense, np.random.default_rng(1))
    out = wp.zeros((len(ijk), 6), dtype=float, device=device)
    wp.launch(lookup_float, len(ijk), inputs=[grid.id, wp.array(ijk, dtype=wp.vec3i, device=device),
              out], backend=backend, device=device)  # fmt: skip
    got = out.numpy()
    want = dense.lookup(ijk.astype(np.int64))
    for col in range(6):
        np.testing.assert_array_equal(got[:, col], want, err_msg=f"column {col}")
    # The voxels reach a leaf value, the lower-node tile and the background.
    assert (want == 5.0).any() and (want == 0.25).any() and (abs(want) < 5.0).any()


def lookup_kernel(dtype, typed_lookup):
    """A kernel looking up ``dtype`` values at vec3i voxels three ways: the typed
    ``typed_lookup(id, ijk)``, ``volume_lookup(id, ijk, dtype=dtype)`` and the typed
    ``(i, j, k)`` form."""

    @wp.kernel
    def lookup(vid: wp.uint64, ijk: wp.array(dtype=wp.vec3i), out: wp.array2d(dtype=Any)):
        t = wp.tid()
        v = ijk[t]
        out[t, 0] = typed_lookup(vid, v)
        out[t, 1] = wp.volume_lookup(vid, v, dtype=dtype)
        out[t, 2] = typed_lookup(vid, v[0], v[1], v[2])

    return wp.overload(lookup, {"out": wp.array2d(dtype=dtype)})


LOOKUPS = {wp.vec3: lookup_kernel(wp.vec3, wp.volume_lookup_v),
           int: lookup_kernel(int, wp.volume_lookup_i)}  # fmt: skip


@pytest.mark.parametrize("backend,device", BACKENDS)
def test_vec3_and_int_lookups_by_vec3i_equal_the_ijk_forms(backend, device):
    rng = np.random.default_rng(3)
    for grid_type, np_dtype, shape, dtype, bg in (
        (GridType.VEC3F, np.float32, (3,), wp.vec3, 0.5), (GridType.INT32, np.int32, (), int, -3),
    ):  # fmt: skip
        data, dense = typed_grid(rng, grid_type, np_dtype, shape, bg)
        grid = GridHandle(data, device)
        ijk = wp.array(voxels(dense, rng, 200), dtype=wp.vec3i, device=device)
        out = wp.zeros((len(ijk), 3), dtype=dtype, device=device)
        wp.launch(LOOKUPS[dtype], len(ijk), inputs=[grid.id, ijk, out], backend=backend,
                  device=device)  # fmt: skip
        want = dense.lookup(ijk.numpy().astype(np.int64))
        for col in range(3):
            np.testing.assert_array_equal(out.numpy()[:, col], want, err_msg=f"column {col}")
        assert (want == bg).any() and (want != bg).any()
    # Float lookups of the int grid give zero in every form (Warp's release behaviour).
    out = wp.full((len(ijk), 6), 1.0, dtype=float, device=device)
    wp.launch(lookup_float, len(ijk), inputs=[grid.id, ijk, out], backend=backend, device=device)
    np.testing.assert_array_equal(out.numpy(), 0.0)


@wp.kernel
def lookup_index(vid: wp.uint64, ijk: wp.array(dtype=wp.vec3i), out: wp.array2d(dtype=int)):
    t = wp.tid()
    v = ijk[t]
    out[t, 0] = wp.volume_lookup_index(vid, v)
    out[t, 1] = wp.volume_lookup_index(vid, v[0], v[1], v[2])


@pytest.mark.parametrize("backend,device", BACKENDS)
def test_index_lookup_by_vec3i_equals_the_ijk_form(backend, device):
    rng = np.random.default_rng(11)
    active = np.unique(rng.integers(-9, 14, (150, 3)), axis=0).astype(np.int32)
    volume = wp.Volume.allocate_by_voxels(wp.array(active, dtype=wp.vec3i, device=device),
                                          voxel_size=1.0, device=device)  # fmt: skip
    ijk = np.concatenate([active, voxels_around(active, rng)]).astype(np.int32)
    out = wp.zeros((len(ijk), 2), dtype=int, device=device)
    wp.launch(lookup_index, len(ijk), inputs=[volume.id, wp.array(ijk, dtype=wp.vec3i,
              device=device), out], backend=backend, device=device)  # fmt: skip
    got = out.numpy()
    np.testing.assert_array_equal(got[:, 0], got[:, 1])
    # Each active voxel has its own index in [0, count); the others have -1.
    n = len(active)
    assert sorted(got[:n, 0]) == list(range(n))
    is_active = {tuple(c) for c in active}
    want_none = [tuple(c) not in is_active for c in ijk[n:]]
    np.testing.assert_array_equal(got[n:, 0] == -1, want_none)
    assert any(want_none) and not all(want_none)


def voxels_around(active: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Voxels near ``active`` (some active, some not)."""
    return active[rng.integers(0, len(active), 100)] + rng.integers(-1, 2, (100, 3))


def store_kernel(dtype, typed_store):
    """A kernel storing ``dtype`` values at vec3i voxels: ``how`` 0 through
    ``volume_store(id, ijk, v)``, 1 the typed ``typed_store(id, ijk, v)``, 2 the typed
    ``(i, j, k)`` form."""

    @wp.kernel
    def store(vid: wp.uint64, ijk: wp.array(dtype=wp.vec3i), v: wp.array(dtype=Any), how: int):
        t = wp.tid()
        if how == 0:
            wp.volume_store(vid, ijk[t], v[t])
        elif how == 1:
            typed_store(vid, ijk[t], v[t])
        else:
            typed_store(vid, ijk[t][0], ijk[t][1], ijk[t][2], v[t])

    return wp.overload(store, {"v": wp.array(dtype=dtype)})


STORES = {
    float: store_kernel(float, wp.volume_store_f),
    wp.vec3: store_kernel(wp.vec3, wp.volume_store_v),
    int: store_kernel(int, wp.volume_store_i),
}


def _grids_after_stores(kernel, data: bytes, ijk, values, device, backend, tiles=None):
    """The grid words after ``kernel`` stores ``values`` at ``ijk`` each of its three ways."""
    out = []
    for how in range(3):
        grid = GridHandle(data, device, tiles=tiles)
        wp.launch(kernel, len(ijk), inputs=[grid.id, wp.array(ijk, dtype=wp.vec3i, device=device),
                  values, how], backend=backend, device=device)  # fmt: skip
        out.append(grid.words.numpy())
    return out


@pytest.mark.parametrize("backend,device", BACKENDS)
def test_stores_by_vec3i_write_what_the_ijk_forms_write(backend, device):
    rng = np.random.default_rng(5)
    data, dense = sparse_float_grid(rng)
    ijk = np.unique(voxels(dense, rng), axis=0)
    new = wp.array(rng.standard_normal(len(ijk)).astype(np.float32), device=device)
    before = GridHandle(data, tiles=TILE).words.numpy()
    a, b, c = _grids_after_stores(STORES[float], data, ijk, new, device, backend, tiles=TILE)
    np.testing.assert_array_equal(a, c)
    np.testing.assert_array_equal(b, c)
    assert (c != before).sum() > 50  # leaf voxels were written

    for grid_type, np_dtype, shape, dtype in (
        (GridType.VEC3F, np.float32, (3,), wp.vec3), (GridType.INT32, np.int32, (), int),
    ):  # fmt: skip
        data, dense = typed_grid(rng, grid_type, np_dtype, shape, 0)
        ijk = np.unique(voxels(dense, rng), axis=0)
        vals = rng.integers(1, 100, (len(ijk), *shape)).astype(np_dtype)
        v = wp.array(vals, dtype=dtype, device=device)
        a, b, c = _grids_after_stores(STORES[dtype], data, ijk, v, device, backend)
        np.testing.assert_array_equal(a, c)
        np.testing.assert_array_equal(b, c)
        assert (c != GridHandle(data).words.numpy()).any()


def test_vec3i_lookups_equal_warps_ijk_lookups_on_the_same_bytes():
    warp = pytest.importorskip("warp")
    warp.config.quiet = True
    data, dense = sparse_float_grid(np.random.default_rng(8))
    grid = GridHandle(data, tiles=TILE)
    wvol = warp.Volume(
        warp.array(grid.words.numpy().view(np.uint8), dtype=warp.uint8, device="cpu")
    )

    @warp.kernel
    def warp_lookup(
        vid: warp.uint64, ijk: warp.array(dtype=warp.vec3i), out: warp.array(dtype=float)
    ):
        t = warp.tid()
        out[t] = warp.volume_lookup_f(vid, ijk[t][0], ijk[t][1], ijk[t][2])

    ijk = voxels(dense, np.random.default_rng(9))
    wout = warp.zeros(len(ijk), dtype=float, device="cpu")
    warp.launch(warp_lookup, len(ijk), inputs=[wvol.id, warp.array(ijk, dtype=warp.vec3i,
                device="cpu"), wout], device="cpu")  # fmt: skip
    out = wp.zeros((len(ijk), 6), dtype=float)
    wp.launch(lookup_float, len(ijk), inputs=[grid.id, wp.array(ijk, dtype=wp.vec3i), out],
              backend="cpu")  # fmt: skip
    for col in range(6):
        np.testing.assert_array_equal(out.numpy()[:, col], wout.numpy(), err_msg=f"column {col}")


def test_vec3i_forms_compile_through_nvrtc():
    """Without a GPU: the kernels above lower to CUDA C that NVRTC compiles (sm_90)."""
    pytest.importorskip("cupy_backends.cuda.libs.nvrtc")
    from kdsl.backends.cuda import BACKEND
    from kdsl.compiler import compile_kernel

    for k in (lookup_float, lookup_index, *LOOKUPS.values(), *STORES.values()):
        compiled = compile_kernel(BACKEND, k.build_module(), k.key, {"arch": "sm_90"})
        assert compiled.payload.cubin("sm_90")[:4] == b"\x7fELF", k.key


@pytest.mark.parametrize("body,match", [
    ("wp.volume_lookup(vid, wp.vec3(1.0))", r"volume_lookup\(\): a voxel is a vec3i or three "
     r"int32s \(i, j, k\), got \(vec<3, f32>\)"),
    ("wp.volume_lookup(vid, wp.vec3l(1, 2, 3))", r"got \(vec<3, i64>\)"),
    ("wp.volume_lookup(vid, 1, 2)", r"volume_lookup\(\): .*got 2 arguments"),
    ("wp.volume_lookup(vid, 1.5, 2, 3)", r"got \(1\.5, 2, 3\)"),
    ("wp.volume_lookup(vid, wp.vec3i(), 1, 2)", r"got \(vec<3, i32>, 1, 2\)"),
    ("wp.volume_store(vid, 1, 2, 1.0)", r"volume_store\(\): .*got 2 arguments"),
    ("wp.volume_store(vid, wp.vec3(), 1.0)", r"volume_store\(\): .*got \(vec<3, f32>\)"),
    ("wp.volume_lookup_f(vid, wp.vec3())", r"no overload of volume_lookup_f\(\).*vec<3, i32>"),
    ("wp.volume_store_i(vid, wp.vec3i(), 1.5)", r"no overload of volume_store_i\(\)"),
    ("wp.volume_lookup_index(vid, wp.vec2i())", r"no overload of volume_lookup_index\(\)"),
])  # fmt: skip
def test_bad_voxel_arguments_are_errors_at_the_call(tmp_path, body, match):
    kernel, path = kernel_from_file(tmp_path, "vid: wp.uint64", body, "bad_voxel")
    with pytest.raises(KdslTypeError, match=match) as err:
        wp.launch(kernel, 1, inputs=[0], backend="interp")
    # The message points at the call: file, line, column and the source line.
    msg = str(err.value)
    assert f'File "{path}", line 5, column 5' in msg and body in msg
