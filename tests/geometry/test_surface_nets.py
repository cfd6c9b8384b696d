"""``kdsl.geometry.IsoSurfaceNets``: Warp's mesh index for index (triangles and quads),
closed surfaces, vertices inside their cells, winding, interp beside cpu, gradients
through ``kdsl.Tape``, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from test_marching_cubes import FIELDS, check_tape_gradient, noise, signed_volume, sphere, torus

import kdsl as wp
import kdsl.geometry
from kdsl.geometry.marching_cubes import MarchingCubesError
from kdsl.geometry.surface_nets import extract_nets

Nets = wp.geometry.IsoSurfaceNets
cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")


def nets(f: np.ndarray, topology: str = "triangle", backend: str | None = None):
    field = wp.array(f, dtype=wp.float32)
    if backend is None:
        v, i = Nets.extract(field, 0.0, topology=topology)
    else:
        v, i = extract_nets(field, 0.0, (0, 0, 0), (1, 1, 1), topology, backend=backend)
    return v.numpy(), i.numpy().reshape(-1, 4 if topology == "quad" else 3)


@pytest.mark.parametrize("name", sorted(FIELDS))
def test_matches_warp(name):
    warp = pytest.importorskip("warp")
    pytest.importorskip("warp.geometry")
    warp.config.quiet = True
    f = FIELDS[name](14)
    for topology in ("triangle", "quad"):
        wv, wi = warp.geometry.IsoSurfaceNets.extract(
            warp.array(f, dtype=warp.float32, device="cpu"), 0.0, topology=topology
        )
        kv, ki = nets(f, topology)
        np.testing.assert_array_equal(ki.ravel(), wi.numpy())
        np.testing.assert_allclose(kv, wv.numpy().reshape(-1, 3), atol=1e-6)


@pytest.mark.parametrize("make", [sphere, torus, noise])
def test_closed_and_outward(make):
    f = make(18)  # each positive on the grid's boundary: closed inside it
    verts, quads = nets(f, "quad")
    edges = np.concatenate([quads[:, [a, (a + 1) % 4]] for a in range(4)])
    keys, counts = np.unique(edges, axis=0, return_counts=True)
    assert (counts == 1).all() and {tuple(k) for k in keys} == {(b, a) for a, b in keys.tolist()}
    assert np.array_equal(np.unique(quads), np.arange(len(verts)))
    _, tris = nets(f)
    assert signed_volume(verts, tris) > 0  # counter-clockwise seen from outside
    # Each vertex is a mean of crossing points on its cell's edges: inside that cell.
    cells = np.floor(verts - 1e-6)
    assert ((verts >= cells - 1e-6) & (verts <= cells + 1 + 1e-6)).all()


def test_interp_matches_cpu():
    f = noise(7, seed=5)
    f[3, 3, 3] = np.nan  # not inside: finite vertices
    for topology in ("triangle", "quad"):
        iv, ii = nets(f, topology, backend="interp")
        cv, ci = nets(f, topology, backend="cpu")
        np.testing.assert_array_equal(ii, ci)
        np.testing.assert_allclose(iv, cv, atol=1e-6)
        assert np.isfinite(cv).all()


def test_context_and_mesh():
    iso = Nets(16, 16, 16, lower=(0, 0, 0), upper=(1, 1, 1), topology="triangle")
    assert isinstance(iso, wp.geometry.IsoSurfaceBase)
    iso.surface(wp.array(sphere(16), dtype=wp.float32), 0.0)
    mesh = wp.Mesh(points=iso.verts, indices=iso.indices)
    assert mesh.points.shape[0] == iso.verts.shape[0] and iso.verts.numpy().max() <= 1.0
    iso.resize(12, 12, 12)
    iso.surface(wp.array(torus(12), dtype=wp.float32), 0.0)
    np.testing.assert_array_equal(iso.indices.numpy().reshape(-1, 3), nets(torus(12))[1])


def test_gradient_through_tape():
    check_tape_gradient(sphere(8), lambda f: Nets.extract(f, 0.0)[0], picks=4, rtol=1e-2)


def test_bad_input():
    with pytest.raises(MarchingCubesError, match="topology"):
        Nets(4, 4, 4, topology="quads")
    with pytest.raises(MarchingCubesError, match="topology"):
        Nets.extract(wp.zeros((4, 4, 4), dtype=wp.float32), topology="tri")
    with pytest.raises(MarchingCubesError, match="does not match"):
        Nets(4, 4, 4).surface(wp.zeros((4, 4, 5), dtype=wp.float32), 0.0)
    with pytest.raises(MarchingCubesError, match="NaN"):
        Nets.extract(wp.zeros((4, 4, 4), dtype=wp.float32), float("nan"))


@cuda
def test_cuda_matches_cpu():
    f = sphere(40)
    for topology in ("triangle", "quad"):
        gv, gi = Nets.extract(wp.array(f, dtype=wp.float32, device="cuda:0"), topology=topology)
        cv, ci = nets(f, topology)
        np.testing.assert_array_equal(gi.numpy(), ci.ravel())
        np.testing.assert_allclose(gv.numpy(), cv, atol=1e-5)
