"""``kdsl.MarchingCubes`` / ``kdsl.geometry.IsoSurfaceMarchingCubes``: the same vertices
and triangles as warp-lang on the same fields, watertight closed surfaces, vertices on
the iso-surface, outward winding, a ``kdsl.Mesh`` built on the output, gradients
through ``kdsl.Tape``, and bad input. The kernels run on interp (small grids, through
``extract_surface``) and cpu; cuda where a GPU is present."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import kdsl as wp
import kdsl.geometry
from kdsl.geometry.marching_cubes import (
    MAX_NODES,
    MarchingCubesError,
    MarchingCubesTypeError,
    extract_surface,
)

cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")


def grid(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    x = np.arange(n, dtype=np.float64)
    return np.meshgrid(x, x, x, indexing="ij")


def sphere(n: int) -> np.ndarray:
    X, Y, Z = grid(n)
    c = (n - 1) / 2 + 0.17  # off the nodes' symmetry planes
    return (np.sqrt((X - c) ** 2 + (Y - c + 0.1) ** 2 + (Z - c) ** 2) - n / 3).astype(np.float32)


def torus(n: int) -> np.ndarray:
    X, Y, Z = grid(n)
    c = (n - 1) / 2
    ring = np.sqrt((X - c) ** 2 + (Z - c - 0.23) ** 2) - n / 4
    return (np.sqrt(ring**2 + (Y - c) ** 2) - n / 9).astype(np.float32)


def noise(n: int, seed: int = 0) -> np.ndarray:
    """Random values, with a boundary layer above the threshold so the surface closes."""
    f = np.random.default_rng(seed).uniform(-1.0, 1.0, (n, n, n)).astype(np.float32)
    f[[0, -1]] = f[:, [0, -1]] = f[:, :, [0, -1]] = 1.0
    return f


def stepped(n: int) -> np.ndarray:
    """Integer values, many exactly at the threshold 0 (which counts as inside)."""
    X, Y, Z = grid(n)
    c = (n - 1) / 2
    return np.round(np.abs(X - c) + np.abs(Y - c) + np.abs(Z - c) - n / 3).astype(np.float32)


CLOSED = {"sphere": sphere, "torus": torus, "noise": noise, "stepped": stepped}
FIELDS = {**CLOSED, "inside": lambda n: np.full((n,) * 3, -1.0, np.float32),
          "outside": lambda n: np.full((n,) * 3, 2.0, np.float32)}  # fmt: skip


def extract(f: np.ndarray, threshold: float = 0.0, backend: str = "cpu", device: str = "cpu"):
    """(verts, triangles) as NumPy arrays."""
    field = wp.array(f, dtype=wp.float32, device=device)
    if backend == "interp":
        v, i = extract_surface(field, threshold, (0, 0, 0), (1, 1, 1), backend="interp")
    else:
        mc = wp.MarchingCubes(*f.shape, device=device)
        mc.surface(field, threshold)
        v, i = mc.verts, mc.indices
    assert v.dtype is wp.vec3 and i.dtype is wp.int32 and v.device == i.device == device
    return v.numpy(), i.numpy().reshape(-1, 3)


def warp_extract(f: np.ndarray, threshold: float = 0.0):
    warp = pytest.importorskip("warp")
    pytest.importorskip("warp.geometry")  # Warp's submodule must be imported explicitly

    warp.config.quiet = True
    v, i = warp.geometry.IsoSurfaceMarchingCubes.extract(
        warp.array(f, dtype=warp.float32, device="cpu"), threshold
    )
    return v.numpy(), i.numpy().reshape(-1, 3)


def edge_uses(tris: np.ndarray) -> dict[tuple[int, int], int]:
    """How many triangles use each directed edge."""
    directed = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    keys, counts = np.unique(directed, axis=0, return_counts=True)
    return {tuple(k): c for k, c in zip(keys.tolist(), counts.tolist(), strict=True)}


def check_watertight(verts: np.ndarray, tris: np.ndarray) -> None:
    """Every edge is used by exactly two triangles, once in each direction (a closed,
    consistently wound surface), and every vertex is used."""
    uses = edge_uses(tris)
    assert all(c == 1 for c in uses.values())
    assert all((b, a) in uses for a, b in uses)
    assert np.array_equal(np.unique(tris), np.arange(len(verts)))


def trilinear(f: np.ndarray, p: np.ndarray) -> np.ndarray:
    """The field's trilinear interpolant at grid-index positions ``p``, in float64."""
    f = f.astype(np.float64)
    lo = np.clip(np.floor(p).astype(int), 0, np.array(f.shape) - 2)
    t = p - lo
    out = np.zeros(len(p))
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                w = (np.where(dx, t[:, 0], 1 - t[:, 0]) * np.where(dy, t[:, 1], 1 - t[:, 1])
                     * np.where(dz, t[:, 2], 1 - t[:, 2]))  # fmt: skip
                out += w * f[lo[:, 0] + dx, lo[:, 1] + dy, lo[:, 2] + dz]
    return out


def signed_volume(verts: np.ndarray, tris: np.ndarray) -> float:
    p = verts.astype(np.float64)
    a, b, c = p[tris[:, 0]], p[tris[:, 1]], p[tris[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6)


@pytest.mark.parametrize("name", sorted(FIELDS))
@pytest.mark.parametrize("backend", ["interp", "cpu"])
def test_surfaces(backend, name):
    n = 9 if backend == "interp" else 24
    f = FIELDS[name](n)
    verts, tris = extract(f, 0.0, backend)
    if name in ("inside", "outside"):
        assert verts.shape == (0, 3) and tris.shape == (0, 3)
        return
    assert len(tris) > 0 and np.isfinite(verts).all()
    check_watertight(verts, tris)
    # Each vertex lies on a grid edge (Warp's lerp rounds the other two coordinates),
    # where the trilinear interpolant is linear: it is the threshold there.
    off_grid = np.abs(verts - np.round(verts)) > 1e-5
    assert (off_grid.sum(axis=1) <= 1).all()
    np.testing.assert_allclose(trilinear(f, verts.astype(np.float64)), 0.0, atol=2e-5)
    # Triangles wind counter-clockwise seen from where the field is below the threshold
    # (outside a signed distance field): the enclosed volume is positive.
    assert signed_volume(verts, tris) > 0


@pytest.mark.parametrize("backend", ["interp", "cpu"])
def test_sphere_vertices_near_the_true_sphere(backend):
    n = 10 if backend == "interp" else 32
    c, r = (n - 1) / 2 + 0.17, n / 3
    verts, tris = extract(sphere(n), 0.0, backend)
    d = np.linalg.norm(verts.astype(np.float64) - [c, c - 0.1, c], axis=1)
    # Linear interpolation of the distance along an edge of length 1: its error is about
    # the curvature 1 / r times 1 / 8, larger where an edge grazes the sphere.
    assert np.abs(d - r).max() < 0.25 / r
    np.testing.assert_allclose(signed_volume(verts, tris), 4 / 3 * np.pi * r**3, rtol=0.08)


def test_interp_and_cpu_agree_exactly():
    f = noise(8, seed=4)
    f[3, 3, 3] = np.nan  # a NaN is outside: the surface around it stays closed
    iv, it = extract(f, 0.1, "interp")
    cv, ct = extract(f, 0.1, "cpu")
    np.testing.assert_array_equal(it, ct)
    np.testing.assert_allclose(iv, cv, atol=1e-6)
    check_watertight(cv, ct)


@pytest.mark.parametrize("name", sorted(FIELDS))
def test_matches_warp(name):
    f = FIELDS[name](20)
    wv, wt = warp_extract(f, 0.0)
    kv, kt = extract(f, 0.0)
    assert kv.shape == wv.shape and kt.shape == wt.shape  # vertex and triangle counts
    np.testing.assert_array_equal(kt, wt)  # same order, same winding, same welding
    np.testing.assert_allclose(kv, wv, atol=1e-5)


def test_matches_warp_with_bounds_and_a_threshold():
    warp = pytest.importorskip("warp")
    pytest.importorskip("warp.geometry")

    warp.config.quiet = True
    f = torus(17)[:, :13, :15].copy()  # different node counts per axis
    lower, upper = (-1.0, 0.5, 2.0), (1.0, 2.0, 3.5)
    wv, wi = warp.geometry.IsoSurfaceMarchingCubes.extract(
        warp.array(f, dtype=warp.float32, device="cpu"), 0.4, lower=lower, upper=upper
    )
    kv, ki = wp.geometry.IsoSurfaceMarchingCubes.extract(
        wp.array(f, dtype=wp.float32), 0.4, lower=lower, upper=upper
    )
    np.testing.assert_array_equal(ki.numpy(), wi.numpy())
    np.testing.assert_allclose(kv.numpy(), wv.numpy(), atol=1e-6)


def test_tables_are_warps():
    pytest.importorskip("warp")
    from warp._src.geometry import marching_cubes as wmc

    iso = wp.geometry.IsoSurfaceMarchingCubes
    assert iso.CASE_TO_TRI_RANGE == wmc.MC_CASE_TO_TRI_RANGE
    assert iso.TRI_LOCAL_INDICES == wmc.MC_TRI_LOCAL_INDICES
    assert iso.CUBE_CORNER_OFFSETS == wmc.MC_CUBE_CORNER_OFFSETS
    assert iso.EDGE_TO_CORNERS == wmc.MC_EDGE_TO_CORNERS


def test_mesh_takes_the_output():
    n = 24
    mc = wp.MarchingCubes(n, n, n, domain_bounds_lower_corner=(0, 0, 0),
                          domain_bounds_upper_corner=(1, 1, 1))  # fmt: skip
    mc.surface(wp.array(sphere(n), dtype=wp.float32), 0.0)
    mesh = wp.Mesh(points=mc.verts, indices=mc.indices)
    verts = mc.verts.numpy()

    @wp.kernel
    def closest(mesh: wp.uint64, q: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec3)):
        i = wp.tid()
        r = wp.mesh_query_point(mesh, q[i], 10.0)
        out[i] = wp.vec3(r.sign, float(r.result), 0.0)

    centre = np.full(3, ((n - 1) / 2 + 0.17) / (n - 1), np.float32)
    centre[1] -= 0.1 / (n - 1)
    q = wp.array([centre, [0.02, 0.02, 0.02]], dtype=wp.vec3)
    out = wp.zeros(2, dtype=wp.vec3)
    wp.launch(closest, dim=2, inputs=[mesh.id, q, out])
    sign, found = out.numpy()[:, 0], out.numpy()[:, 1]
    assert found.all() and sign[0] < 0 < sign[1]  # inside the sphere, then outside
    assert verts.min() >= 0 and verts.max() <= 1


def test_context_reuse_and_resize():
    mc = wp.MarchingCubes(12, 12, 12, max_verts=10, max_tris=10)  # too small: bounds nothing
    mc.surface(wp.array(sphere(12), dtype=wp.float32), 0.0)
    first_verts, first_indices = mc.verts, mc.indices
    kept = first_verts.numpy().copy()
    assert first_verts.shape[0] > mc.max_verts and first_indices.shape[0] > 3 * mc.max_tris
    mc.surface(wp.array(torus(12), dtype=wp.float32), 0.0)
    # New arrays each call: a mesh built on the first surface keeps its points.
    assert mc.verts is not first_verts
    np.testing.assert_array_equal(first_verts.numpy(), kept)
    np.testing.assert_array_equal(mc.indices.numpy().reshape(-1, 3), extract(torus(12))[1])
    mc.resize(16, 10, 12)
    assert (mc.nx, mc.ny, mc.nz) == (16, 10, 12)
    f = sphere(16)[:, :10, :12].copy()
    mc.surface(wp.array(f, dtype=wp.float32), 0.0)
    _, it = extract_surface(wp.array(f, dtype=wp.float32), 0.0, (0, 0, 0), (1, 1, 1))
    np.testing.assert_array_equal(mc.indices.numpy(), it.numpy())


def test_strided_field():
    f = sphere(20)
    big = np.zeros((20, 40, 20), np.float32)
    big[:, ::2] = f
    view = wp.array(big, dtype=wp.float32)[:, ::2]
    assert not view.is_contiguous
    v, i = wp.geometry.IsoSurfaceMarchingCubes.extract(view, 0.0)
    ev, et = extract(f)
    np.testing.assert_array_equal(i.numpy().reshape(-1, 3), et)
    np.testing.assert_array_equal(v.numpy(), ev)


def test_non_finite_values_put_vertices_on_the_finite_end():
    f = sphere(16)
    base_verts, base_tris = extract(f)
    g = f.copy()
    # Next to the surface: replacing a value by a non-finite one of the same side (a NaN
    # is outside, as a negative value is) keeps the topology; the vertices on the
    # changed nodes' crossing edges move to the edge's finite end.
    below = np.argwhere((f < 0) & (f > -0.6))
    above = np.argwhere((f >= 0) & (f < 0.6))
    g[tuple(below[0])], g[tuple(below[len(below) // 2])] = -np.inf, np.nan
    g[tuple(above[len(above) // 3])] = np.inf
    verts, tris = extract(g)
    np.testing.assert_array_equal(tris, base_tris)
    assert np.isfinite(verts).all()
    moved = np.any(verts != base_verts, axis=1)
    assert 3 <= moved.sum() <= 18
    np.testing.assert_array_equal(verts[moved], np.round(verts[moved]))  # on grid nodes
    check_watertight(verts, tris)
    wp.Mesh(points=wp.array(verts, dtype=wp.vec3), indices=wp.array(tris.ravel(), dtype=wp.int32))


@wp.kernel
def weighted_sum(v: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
    i = wp.tid()
    wp.atomic_add(out, 0, wp.dot(v[i], wp.vec3(1.0, 2.0, 3.0)))


def weighted_loss(verts: np.ndarray) -> float:
    """``weighted_sum`` in float64 on the host."""
    return float(verts.astype(np.float64).sum(axis=0) @ [1.0, 2.0, 3.0])


def check_tape_gradient(values: np.ndarray, surface, picks: int, rtol: float) -> None:
    """The gradient of ``weighted_sum(surface(values))`` through ``kdsl.Tape`` against
    central differences at ``picks`` of the entries it reaches; ``surface`` maps a kdsl
    float32 array shaped as ``values`` to vertices."""
    field = wp.array(values, dtype=wp.float32, requires_grad=True)
    out = wp.zeros(1, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        verts = surface(field)
        wp.launch(weighted_sum, dim=verts.shape[0], inputs=[verts, out])
    assert verts.requires_grad
    tape.backward(loss=out)
    grad = field.grad.numpy()
    hot = np.argwhere(np.abs(grad) > 1e-2)
    assert len(hot) >= picks
    for idx in map(tuple, hot[:: len(hot) // picks][:picks]):
        up, down = values.copy(), values.copy()
        up[idx] += 1e-3
        down[idx] -= 1e-3
        diff = weighted_loss(surface(wp.array(up)).numpy()) - weighted_loss(
            surface(wp.array(down)).numpy()
        )
        np.testing.assert_allclose(grad[idx], diff / 2e-3, rtol=rtol)


def test_gradient_through_tape():
    mc = wp.MarchingCubes(8, 8, 8)

    def surface(field):
        mc.surface(field, 0.0)
        return mc.verts

    check_tape_gradient(sphere(8), surface, picks=5, rtol=1e-2)


def test_bounds_aliases():
    iso = wp.geometry.IsoSurfaceMarchingCubes(4, 4, 4, (0, 0, 0), (1, 1, 1))
    with pytest.warns(DeprecationWarning):
        assert iso.domain_bounds_upper_corner == (1, 1, 1)
    with pytest.warns(DeprecationWarning):
        old = wp.geometry.IsoSurfaceMarchingCubes(4, 4, 4, domain_bounds_lower_corner=(1, 2, 3))
    assert old.lower == (1, 2, 3)
    mc = wp.MarchingCubes(4, 4, 4, 0, 0, None, (1, 2, 3))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the older class's own attributes: no warning
        assert mc.domain_bounds_lower_corner == (1, 2, 3) == mc.lower
    assert isinstance(mc, wp.geometry.IsoSurfaceBase) and mc.id == 0
    assert mc.device == wp.get_device("cpu")


def test_bad_input():
    mc = wp.MarchingCubes(6, 6, 6)
    good = wp.zeros((6, 6, 6), dtype=wp.float32)
    with pytest.raises(MarchingCubesTypeError, match="float32"):
        mc.surface(wp.zeros((6, 6, 6), dtype=wp.float64), 0.0)
    with pytest.raises(MarchingCubesError, match="3-d"):
        mc.surface(wp.zeros((6, 36), dtype=wp.float32), 0.0)
    with pytest.raises(MarchingCubesError, match="does not match"):
        mc.surface(wp.zeros((6, 6, 7), dtype=wp.float32), 0.0)
    with pytest.raises(MarchingCubesTypeError, match=r"kdsl\.array"):
        mc.surface(np.zeros((6, 6, 6), np.float32), 0.0)
    with pytest.raises(MarchingCubesError, match="NaN"):
        mc.surface(good, float("nan"))
    with pytest.raises(MarchingCubesTypeError, match="threshold"):
        mc.surface(good, "0.5")
    with pytest.raises(MarchingCubesError, match="at least 2 nodes"):
        wp.geometry.IsoSurfaceMarchingCubes.extract(wp.zeros((1, 6, 6), dtype=wp.float32))
    with pytest.raises(MarchingCubesError, match="too large"):
        wp.MarchingCubes(1024, 1024, 1024)
    with pytest.raises(MarchingCubesError, match="too large"):
        mc.resize(MAX_NODES // 4 + 1, 2, 2)
    with pytest.raises(MarchingCubesError, match="at least 2"):
        wp.MarchingCubes(1, 6, 6)
    with pytest.raises(MarchingCubesTypeError, match="nx must be an int"):
        wp.MarchingCubes(6.0, 6, 6)
    with pytest.raises(MarchingCubesError, match="max_verts"):
        wp.MarchingCubes(6, 6, 6, max_verts=-1)
    with pytest.raises(MarchingCubesTypeError, match="either lower"):
        wp.MarchingCubes(6, 6, 6, domain_bounds_lower_corner=(0, 0, 0), lower=(0, 0, 0))
    with pytest.raises(MarchingCubesError, match="finite"):
        wp.geometry.IsoSurfaceMarchingCubes.extract(good, upper=(1.0, np.nan, 1.0))
    with pytest.raises(MarchingCubesTypeError, match="vec3"):
        wp.geometry.IsoSurfaceMarchingCubes.extract(good, lower=(0.0, 1.0))
    # The errors are Warp's Python classes too.
    assert issubclass(MarchingCubesError, ValueError)
    assert issubclass(MarchingCubesTypeError, TypeError)


@cuda
def test_cuda_matches_cpu():
    for make in (sphere, torus, noise, stepped):
        f = make(40)
        gv, gt = extract(f, 0.0, "cuda", "cuda:0")
        cv, ct = extract(f, 0.0)
        np.testing.assert_array_equal(gt, ct)
        np.testing.assert_allclose(gv, cv, atol=1e-5)


@cuda
def test_cuda_context_refuses_a_cpu_field():
    mc = wp.MarchingCubes(6, 6, 6, device="cuda:0")
    with pytest.raises(MarchingCubesTypeError, match="is on cpu"):
        mc.surface(wp.zeros((6, 6, 6), dtype=wp.float32, device="cpu"), 0.0)
