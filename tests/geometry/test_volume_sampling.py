"""Volume kernel builtins (``kdsl.stdlib.volume``) on grids from kdsl's NanoVDB builder:
sampling (CLOSEST, LINEAR, every value type), lookups, stores, index grids, transforms
and gradients against a NumPy float64 dense-grid reference (trilinear by hand,
background outside active leaves, a lower-node tile value, leaf and root boundaries),
type errors at compile time and in debug builds, and Warp's samples of the same bytes
where warp-lang is installed."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from volume_reference import (
    TILE,
    DenseGrid,
    GridHandle,
    sample_points,
    sparse_float_grid,
    typed_grid,
)

import kdsl as wp
from kdsl.errors import KdslRuntimeError, KdslTypeError
from kdsl.geometry.nanovdb.builder import build_grid, leaves_from_voxels
from kdsl.geometry.nanovdb.layout import GridType
from tests.source_kernels import kernel_from_file

CLOSEST, LINEAR = 0, 1
cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")
BACKENDS = [("interp", "cpu"), ("cpu", "cpu"), pytest.param("cuda", "cuda:0", marks=cuda)]


@pytest.fixture(scope="module")
def float_grid():
    data, dense = sparse_float_grid(np.random.default_rng(7))
    return data, dense


def float_sampler(m):
    """The float sampling kernel in module ``m``'s API (kdsl, or warp for the comparison)."""

    @m.kernel
    def sample_float(vid: m.uint64, p: m.array(dtype=m.vec3), out: m.array2d(dtype=float),
                     grad: m.array(dtype=m.vec3)):  # fmt: skip
        t = m.tid()
        g = m.vec3()
        out[t, 0] = m.volume_sample_f(vid, p[t], CLOSEST)
        out[t, 1] = m.volume_sample_f(vid, p[t], LINEAR)
        out[t, 2] = m.volume_sample_grad_f(vid, p[t], LINEAR, g)
        out[t, 3] = m.volume_sample(vid, p[t], LINEAR, dtype=float)
        out[t, 4] = m.volume_sample_f(vid, p[t] + m.vec3(0.0), LINEAR)
        out[t, 5] = m.volume_lookup_f(vid, int(p[t][0]), int(p[t][1]), int(p[t][2]))
        grad[t] = g

    return sample_float


sample_float = float_sampler(wp)


@pytest.mark.parametrize("backend,device", BACKENDS)
def test_float_sampling_matches_the_dense_reference(float_grid, backend, device):
    data, dense = float_grid
    grid = GridHandle(data, device, tiles=TILE)
    pts = sample_points(np.random.default_rng(1), dense, 400)
    out = wp.zeros((len(pts), 6), dtype=float, device=device)
    grad = wp.zeros(len(pts), dtype=wp.vec3, device=device)
    wp.launch(sample_float, len(pts), inputs=[grid.id, wp.array(pts, dtype=wp.vec3, device=device),
              out, grad], backend=backend, device=device)  # fmt: skip
    got = out.numpy()
    val, g = dense.linear(pts)
    np.testing.assert_array_equal(got[:, 0], dense.closest(pts))
    for col in (1, 2, 3, 4):
        np.testing.assert_allclose(got[:, col], val, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(grad.numpy(), g, rtol=1e-4, atol=1e-4)
    np.testing.assert_array_equal(got[:, 5], dense.lookup(pts.astype(np.int32)))
    # The reference covers the three kinds of places a value comes from.
    looked = dense.lookup(np.floor(pts).astype(np.int64))
    assert (looked == 0.25).any() and (looked == 5.0).any() and (abs(looked) < 5).any()


def sample_generic(dtype):
    """A kernel sampling a volume of ``dtype`` values three ways."""

    @wp.kernel
    def sample(vid: wp.uint64, p: wp.array(dtype=wp.vec3), out: wp.array2d(dtype=Any),
               grad: wp.array(dtype=Any)):  # fmt: skip
        t = wp.tid()
        g = grad[t]
        out[t, 0] = wp.volume_sample(vid, p[t], CLOSEST, dtype=dtype)
        out[t, 1] = wp.volume_sample_grad(vid, p[t], LINEAR, g, dtype=dtype)
        out[t, 2] = wp.volume_lookup(vid, int(p[t][0]), 1 - int(p[t][1]), int(p[t][2]),
                                     dtype=dtype)  # fmt: skip
        grad[t] = g

    return sample


TYPES = [
    (GridType.DOUBLE, np.float64, (), wp.float64, wp.vec3d),
    (GridType.VEC3F, np.float32, (3,), wp.vec3, wp.mat33),
    (GridType.VEC4D, np.float64, (4,), wp.vec4d, wp.matrix(shape=(4, 3), dtype=wp.float64)),
    (GridType.INT32, np.int32, (), wp.int32, wp.vec3i),
    (GridType.INT64, np.int64, (), wp.int64, wp.vec3l),
    (GridType.UINT32, np.uint32, (), wp.uint32, wp.vec3ui),
]


@pytest.mark.parametrize("grid_type,np_dtype,shape,dtype,grad_type", TYPES)
def test_every_value_type(grid_type, np_dtype, shape, dtype, grad_type):
    data, dense = typed_grid(np.random.default_rng(3), grid_type, np_dtype, shape, 7)
    grid = GridHandle(data)
    pts = sample_points(np.random.default_rng(2), dense, 64)
    out = wp.zeros((len(pts), 3), dtype=dtype)
    grad = wp.zeros(len(pts), dtype=grad_type)
    wp.launch(sample_generic(dtype), len(pts), inputs=[grid.id, wp.array(pts, dtype=wp.vec3), out, grad],
              backend="cpu")  # fmt: skip
    got = out.numpy().astype(np.float64)
    np.testing.assert_array_equal(got[:, 0], dense.closest(pts))
    ijk = np.stack([pts[:, 0].astype(np.int32), 1 - pts[:, 1].astype(np.int32),
                    pts[:, 2].astype(np.int32)], 1)  # fmt: skip
    np.testing.assert_array_equal(got[:, 2], dense.lookup(ijk))
    if np.issubdtype(np_dtype, np.floating):
        val, g = dense.linear(pts)
        tol = 1e-5 if np_dtype == np.float32 else 1e-6
        np.testing.assert_allclose(got[:, 1], val, rtol=tol, atol=tol)
        np.testing.assert_allclose(grad.numpy().reshape(g.shape), g, rtol=10 * tol, atol=10 * tol)
    else:
        # Warp's arithmetic: integer grids truncate the trilinear weights, so LINEAR gives
        # the base voxel at integer points and zero between them.
        at_int = np.all(pts == np.floor(pts), axis=1)
        want = np.where(at_int, dense.lookup(np.floor(pts).astype(np.int64)), 0)
        np.testing.assert_array_equal(got[:, 1], want)


@wp.kernel
def store_values(vid: wp.uint64, ijk: wp.array(dtype=wp.vec3i), v: wp.array(dtype=float)):
    t = wp.tid()
    wp.volume_store_f(vid, ijk[t][0], ijk[t][1], ijk[t][2], v[t])


@wp.kernel
def store_vec3(vid: wp.uint64, ijk: wp.array(dtype=wp.vec3i), v: wp.array(dtype=wp.vec3)):
    t = wp.tid()
    wp.volume_store(vid, ijk[t][0], ijk[t][1], ijk[t][2], v[t])


@wp.kernel
def lookup_values(vid: wp.uint64, ijk: wp.array(dtype=wp.vec3i), out: wp.array(dtype=float)):
    t = wp.tid()
    out[t] = wp.volume_lookup_f(vid, ijk[t][0], ijk[t][1], ijk[t][2])


@pytest.mark.parametrize("backend,device", BACKENDS)
def test_store_round_trip(float_grid, backend, device):
    data, dense = float_grid
    grid = GridHandle(data, device, tiles=TILE)
    rng = np.random.default_rng(5)
    ijk = rng.integers(dense.lo - 2, dense.lo + np.array(dense.values.shape) + 2, (300, 3))
    ijk = np.unique(ijk, axis=0).astype(np.int32)
    new = rng.standard_normal(len(ijk)).astype(np.float32)
    wp.launch(store_values, len(ijk), backend=backend, device=device, inputs=[
        grid.id, wp.array(ijk, dtype=wp.vec3i, device=device), wp.array(new, device=device)])  # fmt: skip
    out = wp.zeros(len(ijk), dtype=float, device=device)
    wp.launch(lookup_values, len(ijk), backend=backend, device=device,
              inputs=[grid.id, wp.array(ijk, dtype=wp.vec3i, device=device), out])  # fmt: skip
    # Voxels of leaves (active or not) take the value; tiles and the background do not.
    origins = _leaf_origins(grid)
    leaf = np.array([tuple(o) in origins for o in ijk & ~7])
    want = np.where(leaf, new, dense.lookup(ijk.astype(np.int64)))
    np.testing.assert_array_equal(out.numpy(), want)
    assert leaf.any() and not leaf.all()
    # A vec3 store into a float grid writes nothing.
    wp.launch(store_vec3, len(ijk), backend=backend, device=device, inputs=[
        grid.id, wp.array(ijk, dtype=wp.vec3i, device=device),
        wp.zeros(len(ijk), dtype=wp.vec3, device=device)])  # fmt: skip
    wp.launch(lookup_values, len(ijk), backend=backend, device=device,
              inputs=[grid.id, wp.array(ijk, dtype=wp.vec3i, device=device), out])  # fmt: skip
    np.testing.assert_array_equal(out.numpy(), want)


def _leaf_origins(grid: GridHandle) -> set[tuple[int, int, int]]:
    info = grid.info
    raw = np.frombuffer(info.data, np.uint8)
    out = set()
    for n in range(info.leaf_count):
        at = info.leaf_offset + n * info.layout.leaf_size
        out.add(tuple(int(c) & ~7 for c in np.frombuffer(raw[at : at + 12].tobytes(), np.int32)))
    return out


def index_grid(rng: np.random.Generator):
    """An OnIndex grid of random active voxels (two leaves partly active), its active
    coordinates in leaf order and the per-voxel data."""
    box = np.argwhere(rng.random((14, 9, 8)) < 0.6) + np.array([-6, 4, 2])
    data = build_grid(leaves_from_voxels(box, None, 0), GridType.ONINDEX, 0, np.eye(3),
                      (0.0, 0.0, 0.0))  # fmt: skip
    # OnIndex numbering: leaves in the builder's order, voxels by position in the leaf.
    leaf = box & ~7
    order = np.lexsort((box[:, 2] & 7, box[:, 1] & 7, box[:, 0] & 7, leaf[:, 2], leaf[:, 1],
                        leaf[:, 0]))  # fmt: skip
    return data, box[order]


@wp.kernel
def sample_index(vid: wp.uint64, p: wp.array(dtype=wp.vec3), data: wp.array(dtype=float),
                 bg: float, out: wp.array2d(dtype=float), grad: wp.array(dtype=wp.vec3)):  # fmt: skip
    t = wp.tid()
    g = wp.vec3()
    out[t, 0] = wp.volume_sample_index(vid, p[t], CLOSEST, data, bg)
    out[t, 1] = wp.volume_sample_grad_index(vid, p[t], LINEAR, data, bg, g)
    out[t, 2] = float(wp.volume_lookup_index(vid, int(p[t][0]), int(p[t][1]), int(p[t][2])))
    out[t, 3] = float(wp.volume_voxel_count(vid))
    grad[t] = g


@pytest.mark.parametrize("backend,device", BACKENDS)
def test_index_grid_sampling(backend, device):
    rng = np.random.default_rng(11)
    data, active = index_grid(rng)
    grid = GridHandle(data, device)
    values = rng.standard_normal(len(active)).astype(np.float32)
    # The dense reference: active voxels hold their data, every other voxel the background.
    lo = active.min(0)
    dense_values = np.full(active.max(0) - lo + 1, -0.5)
    dense_values[tuple((active - lo).T)] = values
    dense = DenseGrid(lo, dense_values, np.float64(-0.5))
    pts = sample_points(np.random.default_rng(4), dense, 200)
    out = wp.zeros((len(pts), 4), dtype=float, device=device)
    grad = wp.zeros(len(pts), dtype=wp.vec3, device=device)
    wp.launch(sample_index, len(pts), backend=backend, device=device, inputs=[
        grid.id, wp.array(pts, dtype=wp.vec3, device=device), wp.array(values, device=device),
        -0.5, out, grad])  # fmt: skip
    got = out.numpy()
    val, g = dense.linear(pts)
    np.testing.assert_array_equal(got[:, 0], dense.closest(pts))
    np.testing.assert_allclose(got[:, 1], val, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(grad.numpy(), g, rtol=1e-4, atol=1e-4)
    index_of = {tuple(c): n for n, c in enumerate(active)}
    want = [index_of.get(tuple(c), -1) for c in pts.astype(np.int32)]
    np.testing.assert_array_equal(got[:, 2], want)
    assert got[0, 3] == len(active)


@wp.kernel
def world_loss(vid: wp.uint64, x: wp.array(dtype=wp.vec3), loss: wp.array(dtype=float)):
    t = wp.tid()
    uvw = wp.volume_world_to_index(vid, x[t])
    wp.atomic_add(loss, 0, wp.volume_sample_f(vid, uvw, LINEAR) * float(t % 3 + 1))


@wp.kernel
def index_loss(vid: wp.uint64, p: wp.array(dtype=wp.vec3), data: wp.array(dtype=float),
               bg: wp.array(dtype=float), loss: wp.array(dtype=float)):  # fmt: skip
    t = wp.tid()
    v = wp.volume_sample_index(vid, p[t], LINEAR, data, bg[0])
    wp.atomic_add(loss, 0, v * v)


def _affine_grid(rng):
    """``sparse_float_grid``'s values with a sheared, scaled, translated transform."""
    mat = np.array([[0.5, 0.1, 0.0], [0.0, 0.4, 0.05], [0.02, 0.0, 0.6]])
    data, dense = sparse_float_grid(rng)
    keep = (dense.values != dense.background) & (dense.values != TILE[0, 120, 0])
    ijk = np.argwhere(keep) + dense.lo
    data = build_grid(leaves_from_voxels(ijk, dense.values[keep].astype(np.float32),
                      np.float32(0.25)), GridType.FLOAT, np.float32(0.25), mat, (1.0, -2.0, 0.5))  # fmt: skip
    return data, DenseGrid(dense.lo, np.where(keep, dense.values, 0.25), dense.background), mat


def tape_grad_by_points(kernel, vid: int, points: np.ndarray, backend: str) -> np.ndarray:
    """The Tape gradient of ``kernel``'s loss (its last argument) by its points (the second)."""
    pa = wp.array(points, dtype=wp.vec3, requires_grad=True)
    loss = wp.zeros(1, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(kernel, len(points), inputs=[vid, pa, loss], backend=backend)
    tape.backward(loss)
    return pa.grad.numpy()


def off_faces(p: np.ndarray, margin: float) -> np.ndarray:
    """The points of ``p`` at least ``margin`` from every integer plane (inside one cell)."""
    return p[np.all(abs(p - np.round(p)) > margin, axis=1)]


@pytest.mark.parametrize("backend", ["interp", "cpu"])
def test_gradient_by_world_position_matches_the_reference(backend):
    data, dense, mat = _affine_grid(np.random.default_rng(9))
    grid = GridHandle(data)
    uvw = off_faces(sample_points(np.random.default_rng(3), dense, 60), 0.01)
    x = (uvw.astype(np.float64) @ mat.T + [1.0, -2.0, 0.5]).astype(np.float32)
    grad = tape_grad_by_points(world_loss, grid.id, x, backend)
    w = (np.arange(len(x)) % 3 + 1)[:, None]
    # d sample / d x = (d sample / d uvw) @ world_to_index: the true transpose (Warp's float32
    # adjoint multiplies by the matrix itself).
    _, g = dense.linear(np.linalg.solve(mat, (x - [1.0, -2.0, 0.5]).T).T)
    np.testing.assert_allclose(grad, w * g @ np.linalg.inv(mat), rtol=2e-3, atol=2e-3)


@pytest.mark.parametrize("backend", ["interp", "cpu"])
def test_index_gradients_reach_the_data_and_background(backend):
    rng = np.random.default_rng(12)
    data, active = index_grid(rng)
    grid = GridHandle(data)
    values = rng.standard_normal(len(active)).astype(np.float32)
    pts = active[rng.integers(0, len(active), 40)] + rng.uniform(-0.9, 0.9, (40, 3))
    pts = pts.astype(np.float32)
    d = wp.array(values, requires_grad=True)
    bg = wp.array([0.3], dtype=float, requires_grad=True)
    pa = wp.array(pts, dtype=wp.vec3)
    loss = wp.zeros(1, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(index_loss, len(pts), inputs=[grid.id, pa, d, bg, loss], backend=backend)
    tape.backward(loss)

    # Linear in the data: the loss gradient is 2 v(p) * weight(p, voxel), summed.
    lo = active.min(0)
    dense = np.zeros(active.max(0) - lo + 1, np.int64) - 1
    dense[tuple((active - lo).T)] = np.arange(len(active))
    want_d = np.zeros(len(active))
    want_bg = 0.0
    base = np.floor(pts.astype(np.float64))
    frac = pts - base
    vals64 = values.astype(np.float64)
    for p in range(len(pts)):
        corners = []
        for c in np.ndindex(2, 2, 2):
            ijk = base[p].astype(np.int64) + c - lo
            inside = np.all((ijk >= 0) & (ijk < dense.shape))
            n = dense[tuple(ijk)] if inside else -1
            w = np.prod(np.where(np.array(c) == 1, frac[p], 1.0 - frac[p]))
            corners.append((n, w))
        v = sum(w * (vals64[n] if n >= 0 else 0.3) for n, w in corners)
        for n, w in corners:
            if n >= 0:
                want_d[n] += 2 * v * w
            else:
                want_bg += 2 * v * w
    np.testing.assert_allclose(d.grad.numpy(), want_d, rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(bg.grad.numpy()[0], want_bg, rtol=1e-4, atol=1e-5)


@wp.kernel
def transforms(vid: wp.uint64, p: wp.array(dtype=wp.vec3), out: wp.array2d(dtype=wp.vec3),
               out64: wp.array2d(dtype=wp.vec3d)):  # fmt: skip
    t = wp.tid()
    q = wp.vec3d(p[t])
    out[t, 0] = wp.volume_index_to_world(vid, p[t])
    out[t, 1] = wp.volume_world_to_index(vid, p[t])
    out[t, 2] = wp.volume_index_to_world_dir(vid, p[t])
    out[t, 3] = wp.volume_world_to_index_dir(vid, p[t])
    out[t, 4] = wp.volume_transform(vid, p[t])
    out[t, 5] = wp.volume_transform_inv(vid, p[t])
    out64[t, 0] = wp.volume_index_to_world(vid, q)
    out64[t, 1] = wp.volume_world_to_index(vid, q)
    out64[t, 2] = wp.volume_index_to_world_dir(vid, q)
    out64[t, 3] = wp.volume_world_to_index_dir(vid, q)


@wp.kernel
def sample_world(vid: wp.uint64, x: wp.array(dtype=wp.vec3), out: wp.array2d(dtype=float)):
    t = wp.tid()
    out[t, 0] = wp.volume_sample_world(vid, x[t], LINEAR)
    out[t, 1] = wp.volume_sample_local(vid, wp.volume_world_to_index(vid, x[t]), LINEAR)


@pytest.mark.parametrize("backend,device", BACKENDS)
def test_transforms_and_older_names(backend, device):
    data, dense, mat = _affine_grid(np.random.default_rng(9))
    grid = GridHandle(data, device)
    p = np.random.default_rng(0).uniform(-20, 20, (32, 3)).astype(np.float32)
    out = wp.zeros((32, 6), dtype=wp.vec3, device=device)
    out64 = wp.zeros((32, 4), dtype=wp.vec3d, device=device)
    wp.launch(transforms, 32, inputs=[grid.id, wp.array(p, dtype=wp.vec3, device=device), out,
              out64], backend=backend, device=device)  # fmt: skip
    t, inv = np.array([1.0, -2.0, 0.5]), np.linalg.inv(mat)
    p64 = p.astype(np.float64)
    want = [p64 @ mat.T + t, (p64 - t) @ inv.T, p64 @ mat.T, p64 @ inv.T]
    got, got64 = out.numpy(), out64.numpy()
    for k, w in enumerate(want):
        np.testing.assert_allclose(got[:, k], w, rtol=1e-5, atol=1e-4)
        np.testing.assert_allclose(got64[:, k], w, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(got[:, 4], got[:, 0])
    np.testing.assert_array_equal(got[:, 5], got[:, 1])
    # volume_sample_world samples at the index point of a world point.
    uvw = off_faces(sample_points(np.random.default_rng(5), dense, 50), 0.01).astype(np.float64)
    x = (uvw @ mat.T + t).astype(np.float32)
    s = wp.zeros((len(x), 2), dtype=float, device=device)
    wp.launch(sample_world, len(x), inputs=[grid.id, wp.array(x, dtype=wp.vec3, device=device), s],
              backend=backend, device=device)  # fmt: skip
    np.testing.assert_allclose(s.numpy()[:, 0], dense.linear(uvw)[0], rtol=1e-4, atol=1e-4)
    np.testing.assert_array_equal(s.numpy()[:, 1], s.numpy()[:, 0])


@wp.kernel(debug=True)
def sample_f_debug(vid: wp.uint64, out: wp.array(dtype=float)):
    out[0] = wp.volume_sample_f(vid, wp.vec3(3.5, -8.5, 61.5), LINEAR)


@wp.kernel
def sample_f_release(vid: wp.uint64, out: wp.array(dtype=float), outi: wp.array(dtype=int)):
    out[0] = wp.volume_sample_f(vid, wp.vec3(3.5, -8.5, 61.5), LINEAR)
    outi[0] = wp.volume_sample_i(vid, wp.vec3(3.5, -8.5, 61.5))


@pytest.mark.parametrize("backend", ["interp", "cpu"])
def test_value_type_mismatch(backend):
    data, _ = typed_grid(np.random.default_rng(3), GridType.INT32, np.int32, (), 7)
    grid = GridHandle(data)
    out, outi = wp.full(1, 9.0, dtype=float), wp.zeros(1, dtype=int)
    # Release builds give zero, as Warp; debug builds stop with the record check's error.
    wp.launch(sample_f_release, 1, inputs=[grid.id, out, outi], backend=backend)
    assert out.numpy()[0] == 0.0 and outi.numpy()[0] != 0
    with pytest.raises(KdslRuntimeError, match="as a VolumeFloat32"):
        wp.launch(sample_f_debug, 1, inputs=[grid.id, out], backend=backend)


@pytest.mark.parametrize("body,match", [
    ("wp.volume_sample(vid, wp.vec3(), 1, dtype=wp.mat33)", "unsupported volume type"),
    ("wp.volume_sample(vid, wp.vec3(), 1)", r"needs the volume's value type"),
    ("wp.volume_sample_grad(vid, wp.vec3(), 1, wp.vec3(), dtype=wp.vec3)",
     "incompatible gradient type, expected mat<3, 3, f32>, got vec<3, f32>"),
    ("wp.volume_sample_index(vid, wp.vec3(), 1, d, wp.int32(1))", "must have the same dtype"),
    ("wp.volume_sample_index(vid, wp.vec3(), 1, di, wp.float32(0.5))", "must have the same dtype"),
    ("wp.volume_store(vid, 0, 0, 0, wp.vec2())", "unsupported volume type"),
    ("wp.volume_sample_f(vid, wp.vec3(), 1, 2)", "volume_sample_f"),
])  # fmt: skip
def test_compile_time_type_errors(body, match, tmp_path):
    params = "vid: wp.uint64, d: wp.array(dtype=wp.float32), di: wp.array(dtype=int)"
    bad, _ = kernel_from_file(tmp_path, params, body, "volume_bad")
    with pytest.raises(KdslTypeError, match=match):
        wp.launch(bad, 1, inputs=[0, wp.zeros(1), wp.zeros(1, dtype=int)], backend="interp")


def test_samples_equal_warps_on_the_same_bytes(float_grid):
    warp = pytest.importorskip("warp")
    warp.config.quiet = True
    data, dense = float_grid
    grid = GridHandle(data, tiles=TILE)
    raw = grid.words.numpy().view(np.uint8)
    wvol = warp.Volume(warp.array(raw, dtype=warp.uint8, device="cpu"))

    warp_samples = float_sampler(warp)
    pts = sample_points(np.random.default_rng(8), dense, 300)
    wout = warp.zeros((len(pts), 6), dtype=float, device="cpu")
    wgrad = warp.zeros(len(pts), dtype=warp.vec3, device="cpu")
    warp.launch(warp_samples, len(pts), inputs=[wvol.id, warp.array(pts, dtype=warp.vec3,
                device="cpu"), wout, wgrad], device="cpu")  # fmt: skip
    out = wp.zeros((len(pts), 6), dtype=float)
    grad = wp.zeros(len(pts), dtype=wp.vec3)
    wp.launch(sample_float, len(pts), inputs=[grid.id, wp.array(pts, dtype=wp.vec3), out, grad],
              backend="cpu")  # fmt: skip
    np.testing.assert_allclose(out.numpy(), wout.numpy(), rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(grad.numpy(), wgrad.numpy(), rtol=1e-5, atol=1e-5)


@wp.kernel
def warp_doc_examples(vid: wp.uint64, out: wp.array(dtype=float)):
    # The examples of Warp 1.19's volume builtin docstrings, on a kdsl.Volume.
    p = wp.volume_world_to_index(vid, wp.vec3(0.5, 0.0, 0.0))
    out[0] = wp.volume_sample(vid, p, wp.Volume.LINEAR, dtype=float)
    grad = wp.vec3()
    out[1] = wp.volume_sample_grad(vid, wp.vec3(0.5, 0.0, 0.0), wp.Volume.LINEAR, grad, dtype=float)
    out[2] = grad[0]
    out[3] = wp.volume_lookup(vid, 1, 0, 0, dtype=float)
    wp.volume_store(vid, 1, 2, 3, 4.0)
    out[4] = wp.volume_lookup(vid, 1, 2, 3, dtype=float)


@wp.kernel
def fill_index(vid: wp.uint64, d: wp.array(dtype=wp.float32)):
    i, j, k = wp.tid()
    idx = wp.volume_lookup_index(vid, i, j, k)
    if idx >= 0:
        d[idx] = wp.float32(i) * 10.0


@wp.kernel
def index_doc_examples(vid: wp.uint64, d: wp.array(dtype=wp.float32), out: wp.array(dtype=float)):
    out[0] = wp.volume_sample_index(vid, wp.vec3(0.5, 0.0, 0.0), wp.Volume.LINEAR, d, 0.0)
    grad = wp.vec3()
    out[1] = wp.volume_sample_grad_index(vid, wp.vec3(0.5, 0.0, 0.0), wp.Volume.LINEAR, d, 0.0,
                                         grad)  # fmt: skip
    out[2] = grad[0]
    out[3] = float(wp.volume_lookup_index(vid, 1, 0, 0))
    out[4] = float(wp.volume_voxel_count(vid))
    w = wp.volume_index_to_world(vid, wp.vec3(2.0, 0.0, 0.0))
    out[5] = w[0]


@pytest.mark.parametrize("backend", ["interp", "cpu"])
def test_warps_docstring_examples_on_a_kdsl_volume(backend):
    values = np.zeros((2, 2, 2), dtype=np.float32)
    values[1, :, :] = 1.0  # f(i, j, k) = i
    volume = wp.Volume.load_from_numpy(values, voxel_size=1.0, bg_value=0.0)
    out = wp.zeros(5, dtype=float)
    wp.launch(warp_doc_examples, 1, inputs=[volume.id, out], backend=backend)
    np.testing.assert_allclose(out.numpy(), [0.5, 0.5, 1.0, 1.0, 4.0])
    voxels = wp.array([[0, 0, 0], [1, 0, 0]], dtype=wp.vec3i)
    index = wp.Volume.allocate_by_voxels(voxels, voxel_size=1.0)
    data = wp.zeros(index.get_voxel_count(), dtype=wp.float32)
    wp.launch(fill_index, (2, 1, 1), inputs=[index.id, data], backend=backend)
    out = wp.zeros(6, dtype=float)
    wp.launch(index_doc_examples, 1, inputs=[index.id, data, out], backend=backend)
    np.testing.assert_allclose(out.numpy(), [5.0, 5.0, 10.0, 1.0, 2.0, 2.0])


@wp.kernel
def sample_sum(vid: wp.uint64, p: wp.array(dtype=wp.vec3), loss: wp.array(dtype=float)):
    t = wp.tid()
    wp.atomic_add(loss, 0, wp.volume_sample_f(vid, p[t], LINEAR))


@pytest.mark.parametrize("backend", ["interp", "cpu"])
def test_tape_gradient_by_uvw_matches_finite_differences(float_grid, backend):
    data, dense = float_grid
    grid = GridHandle(data, tiles=TILE)
    pts = off_faces(sample_points(np.random.default_rng(21), dense, 40), 0.03)
    grad = tape_grad_by_points(sample_sum, grid.id, pts, backend)
    h = 1e-2
    fd = np.zeros_like(pts, dtype=np.float64)
    for a in range(3):
        step = np.zeros(3, np.float32)
        step[a] = h
        both = []
        for q in (pts + step, pts - step):
            out = wp.zeros((len(pts), 6), dtype=float)
            wp.launch(sample_float, len(pts), inputs=[grid.id, wp.array(q, dtype=wp.vec3), out,
                      wp.zeros(len(pts), dtype=wp.vec3)], backend=backend)  # fmt: skip
            both.append(out.numpy()[:, 1].astype(np.float64))
        fd[:, a] = (both[0] - both[1]) / (2 * h)
    np.testing.assert_allclose(grad, fd, rtol=5e-3, atol=5e-3)


@wp.kernel
def lookup_indices(vid: wp.uint64, ijk: wp.array(dtype=wp.vec3i), out: wp.array(dtype=int)):
    t = wp.tid()
    out[t] = wp.volume_lookup_index(vid, ijk[t][0], ijk[t][1], ijk[t][2])


@pytest.mark.parametrize("backend", ["interp", "cpu"])
def test_index_grid_of_whole_tiles_numbers_every_leaf_voxel(backend):
    # allocate_by_tiles without a background makes an Index grid: each leaf's 512 voxels
    # are numbered from the leaf's offset, leaves in get_tiles() order.
    tiles = wp.array([[8, 0, -16], [-8, 24, 0]], dtype=wp.vec3i)
    volume = wp.Volume.allocate_by_tiles(tiles, voxel_size=1.0, bg_value=None)
    origins = volume.get_tiles().numpy()
    ijk = np.concatenate([o + np.argwhere(np.ones((8, 8, 8), bool)) for o in origins])
    ijk = np.concatenate([ijk, [[100, 100, 100], [7, 0, -16]]]).astype(np.int32)
    out = wp.zeros(len(ijk), dtype=int)
    wp.launch(lookup_indices, len(ijk), inputs=[volume.id, wp.array(ijk, dtype=wp.vec3i), out],
              backend=backend)  # fmt: skip
    np.testing.assert_array_equal(out.numpy(), [*range(512 * len(origins)), -1, -1])
