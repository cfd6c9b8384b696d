"""``kdsl.geometry.sparse_marching_cubes`` / ``_from_cells`` / ``lipschitz_octree``:
Warp's output index for index, the dense extraction's surface, interp beside cpu,
gradients through ``kdsl.Tape`` and bad input."""

from __future__ import annotations

import numpy as np
import pytest
from test_marching_cubes import check_tape_gradient

import kdsl as wp
import kdsl.geometry
from kdsl.geometry.marching_cubes import MarchingCubesError, MarchingCubesTypeError
from kdsl.geometry.sparse_marching_cubes import kernels_on

geometry = wp.geometry
cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")
CENTRE, RADIUS = (0.5, 0.45, 0.52), 0.3


def sphere_field(lib):
    """A batched signed distance to a sphere, for ``lib`` (kdsl or warp)."""

    @lib.kernel
    def sdf(points: lib.array(dtype=lib.vec3), out: lib.array(dtype=lib.float32)):
        i = lib.tid()
        out[i] = lib.length(points[i] - lib.vec3(0.5, 0.45, 0.52)) - 0.3

    def evaluate(points):
        out = lib.empty(points.shape[0], dtype=lib.float32, device=points.device)
        lib.launch(sdf, dim=points.shape[0], inputs=[points, out], device=points.device)
        return out

    return evaluate


def warp_geometry():
    warp = pytest.importorskip("warp")
    pytest.importorskip("warp.geometry")
    warp.config.quiet = True
    return warp


def corner_samples(cells: np.ndarray) -> np.ndarray:
    """A smooth function of each cell corner's subscript (equal where cells share it)."""
    p = cells[:, None, :] + np.array(geometry.IsoSurfaceMarchingCubes.CUBE_CORNER_OFFSETS)
    f = np.sin(1.3 * p[..., 0]) + np.cos(0.7 * p[..., 1]) + np.sin(2.1 * p[..., 2] + 0.3) - 0.2
    return f.astype(np.float32)


def block(lo, hi) -> np.ndarray:
    r = [np.arange(a, b) for a, b in zip(lo, hi, strict=True)]
    return np.stack(np.meshgrid(*r, indexing="ij"), axis=-1).reshape(-1, 3).astype(np.int32)


def test_matches_warp():
    warp = warp_geometry()
    bounds = {"lower": (0.0, -0.1, 0.05), "upper": (1.0, 1.1, 0.95)}
    # 21 x 18 x 25 nodes: the octree's power-of-two box is culled back to the grid.
    kv, ki, ks = geometry.sparse_marching_cubes(sphere_field(wp), 21, 18, 25, **bounds,
                                                return_stats=True)  # fmt: skip
    wv, wi, ws = warp.geometry.sparse_marching_cubes(sphere_field(warp), 21, 18, 25, **bounds,
                                                     device="cpu", return_stats=True)  # fmt: skip
    assert ks == ws
    np.testing.assert_array_equal(ki.numpy(), wi.numpy())
    np.testing.assert_allclose(kv.numpy(), wv.numpy(), atol=1e-6)

    cells = block((-2, 0, 1), (3, 4, 4))
    values = corner_samples(cells)
    args = {"origin": (0.1, 0.2, 0.3), "cell_width": 0.1, "threshold": 0.25}
    kv, ki = geometry.sparse_marching_cubes_from_cells(cells, values, **args)
    wv, wi = warp.geometry.sparse_marching_cubes_from_cells(cells, values, device="cpu", **args)
    assert ki.shape[0] > 0
    np.testing.assert_array_equal(ki.numpy(), wi.numpy())
    np.testing.assert_allclose(kv.numpy(), wv.numpy(), atol=1e-6)

    kc, kw = geometry.lipschitz_octree(sphere_field(wp), (0.0, 0.0, 0.0), 1.0, 4)
    wc, ww = warp.geometry.lipschitz_octree(sphere_field(warp), (0.0, 0.0, 0.0), 1.0, 4,
                                            device="cpu")  # fmt: skip
    assert kw == ww and kc.dtype is wp.vec3i
    np.testing.assert_array_equal(kc.numpy(), wc.numpy())


def test_same_surface_as_dense_extraction():
    n = 24
    bounds = {"lower": (0.0, 0.0, 0.0), "upper": (1.0, 1.0, 1.0)}
    sv, si, stats = geometry.sparse_marching_cubes(sphere_field(wp), n, n, n, **bounds,
                                                   return_stats=True)  # fmt: skip
    x = np.arange(n, dtype=np.float32) * (np.float32(1.0) / np.float32(n - 1))  # the kernels' nodes
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
    points = wp.array(np.stack([X, Y, Z], -1).reshape(-1, 3), dtype=wp.vec3)
    dense = sphere_field(wp)(points).reshape((n, n, n))
    dv, di = geometry.IsoSurfaceMarchingCubes.extract(dense, 0.0, **bounds)
    # The same vertices and triangles, in another order.
    sv, dv = sv.numpy(), dv.numpy()
    assert sv.shape == dv.shape and si.shape == di.shape
    np.testing.assert_array_equal(np.unique(sv, axis=0), np.unique(dv, axis=0))

    def triangles(v, i):
        return {tuple(map(tuple, v[t])) for t in i.numpy().reshape(-1, 3)}

    assert triangles(sv, si) == triangles(dv, di)
    # Only the cells near the surface were evaluated.
    assert stats["field_evaluations"] < n**3 / 2


def test_interp_matches_cpu():
    cells = block((0, 0, 0), (3, 3, 2))
    values = corner_samples(cells)
    cv, ci = geometry.sparse_marching_cubes_from_cells(cells, values, cell_width=0.5)
    with kernels_on("interp"):
        iv, ii = geometry.sparse_marching_cubes_from_cells(cells, values, cell_width=0.5)
        ov, oi = geometry.sparse_marching_cubes(sphere_field(wp), 7, 6, 7, upper=(1, 1, 1))
    assert ci.shape[0] > 0 and oi.shape[0] > 0
    np.testing.assert_array_equal(ii.numpy(), ci.numpy())
    np.testing.assert_allclose(iv.numpy(), cv.numpy(), atol=1e-6)
    pv, pi = geometry.sparse_marching_cubes(sphere_field(wp), 7, 6, 7, upper=(1, 1, 1))
    np.testing.assert_array_equal(oi.numpy(), pi.numpy())
    np.testing.assert_allclose(ov.numpy(), pv.numpy(), atol=1e-6)


def test_closed_surface_is_watertight():
    verts, indices = geometry.sparse_marching_cubes(sphere_field(wp), 20, 20, 20,
                                                    upper=(1.0, 1.0, 1.0))  # fmt: skip
    tris = indices.numpy().reshape(-1, 3)
    directed = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    keys, counts = np.unique(directed, axis=0, return_counts=True)
    assert (counts == 1).all()
    assert {tuple(k) for k in keys} == {(b, a) for a, b in keys.tolist()}
    d = np.linalg.norm(verts.numpy() - CENTRE, axis=1)
    assert np.abs(d - RADIUS).max() < 0.01
    wp.Mesh(points=verts, indices=indices)


def test_gradient_through_tape():
    cells = block((0, 0, 0), (2, 2, 2))

    def surface(values):
        return geometry.sparse_marching_cubes_from_cells(cells, values)[0]

    # A corner shared by cells takes its value from one entry: the gradient goes there.
    check_tape_gradient(corner_samples(cells).ravel(), surface, picks=3, rtol=2e-2)


def test_empty_results():
    @wp.kernel
    def far(points: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.float32)):
        out[wp.tid()] = 10.0

    def evaluate(points):
        out = wp.empty(points.shape[0], dtype=wp.float32)
        wp.launch(far, dim=points.shape[0], inputs=[points, out])
        return out

    v, i, stats = geometry.sparse_marching_cubes(evaluate, 9, 9, 9, return_stats=True)
    assert v.shape == (0,) and i.shape == (0,) and stats["leaf_cells"] == 0
    v, i = geometry.sparse_marching_cubes_from_cells(np.zeros((0, 3), np.int32), [])
    assert v.shape == (0,) and i.shape == (0,)
    cells, width = geometry.lipschitz_octree(evaluate, (0, 0, 0), 1.0, 3)
    assert cells.shape == (0,) and width == 0.125


def test_bad_input():
    field = sphere_field(wp)

    @wp.func
    def single(p: wp.vec3) -> float:
        return wp.length(p) - 1.0

    with pytest.raises(MarchingCubesTypeError, match="single-point"):
        geometry.sparse_marching_cubes(single, 8, 8, 8)
    with pytest.raises(MarchingCubesTypeError, match="callable"):
        geometry.sparse_marching_cubes(3.0, 8, 8, 8)
    with pytest.raises(MarchingCubesTypeError, match="float32"):
        geometry.sparse_marching_cubes(lambda p: p.numpy(), 8, 8, 8)
    with pytest.raises(MarchingCubesError, match="returned shape"):
        geometry.sparse_marching_cubes(lambda p: wp.zeros(1, dtype=wp.float32), 8, 8, 8)
    with pytest.raises(MarchingCubesError, match="at least 2"):
        geometry.sparse_marching_cubes(field, 1, 8, 8)
    with pytest.raises(MarchingCubesError, match="lipschitz_bound"):
        geometry.sparse_marching_cubes(field, 8, 8, 8, lipschitz_bound=-1.0)
    with pytest.raises(MarchingCubesError, match="NaN"):
        geometry.sparse_marching_cubes(field, 8, 8, 8, threshold=float("nan"))
    with pytest.raises(MarchingCubesError, match="max_depth"):
        geometry.lipschitz_octree(field, (0, 0, 0), 1.0, -1)
    with pytest.raises(MarchingCubesError, match="root_width"):
        geometry.lipschitz_octree(field, (0, 0, 0), 0.0, 3)
    cells = block((0, 0, 0), (2, 2, 2))
    with pytest.raises(MarchingCubesError, match="cell_width"):
        geometry.sparse_marching_cubes_from_cells(cells, corner_samples(cells), cell_width=0.0)
    with pytest.raises(MarchingCubesError, match="8 values per cell"):
        geometry.sparse_marching_cubes_from_cells(cells, np.zeros(7, np.float32))
    with pytest.raises(MarchingCubesTypeError, match="three per cell"):
        geometry.sparse_marching_cubes_from_cells(np.zeros(4, np.int32), np.zeros(8))
    with pytest.raises(MarchingCubesTypeError, match="float32"):
        geometry.sparse_marching_cubes_from_cells(cells, wp.zeros(64, dtype=wp.float64))


@cuda
def test_cuda_matches_cpu():
    args = {"lower": (0.0, 0.0, 0.0), "upper": (1.0, 1.0, 1.0)}
    gv, gi = geometry.sparse_marching_cubes(sphere_field(wp), 33, 30, 35, device="cuda:0", **args)
    cv, ci = geometry.sparse_marching_cubes(sphere_field(wp), 33, 30, 35, **args)
    assert gv.device == "cuda:0"
    np.testing.assert_array_equal(gi.numpy(), ci.numpy())
    np.testing.assert_allclose(gv.numpy(), cv.numpy(), atol=1e-6)
    cells = block((-3, 0, 2), (4, 5, 6))
    values = corner_samples(cells)
    gv, gi = geometry.sparse_marching_cubes_from_cells(cells, values, device="cuda:0")
    cv, ci = geometry.sparse_marching_cubes_from_cells(cells, values)
    np.testing.assert_array_equal(gi.numpy(), ci.numpy())
    np.testing.assert_allclose(gv.numpy(), cv.numpy(), atol=1e-6)
