"""A mesh's check issued before its BVH build and answered after it
(``FaceBoxes.start`` / ``finish``): bad indices and NaN points still raise at
construction (on a cold mesh and on one taking a collected mesh's face boxes), a
refused mesh files nothing, a later good mesh over the same arrays is the mesh a
build of its own gives, and a refit with a bad point keeps the BVH and the edge sum;
the first run of a GPU-config lbvh build (the kdsl merge sort, its merges patched)
gives the tree of a ``SortKeys`` build bit for bit. On cpu here (cuda on the GPU
machine)."""

from __future__ import annotations

import gc

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslTypeError
from kdsl.geometry import lbvh, mesh_refit, recycle

cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")
DEVICES = ["cpu", pytest.param("cuda:0", marks=cuda)]


def grid(cells: int = 8):
    """A bumpy height field: (points, faces) as NumPy arrays."""
    g = np.arange(cells + 1, dtype=np.float32) / cells
    x, y = np.meshgrid(g, g, indexing="ij")
    pts = np.stack([x, y, 0.1 * np.sin(7 * x) * np.cos(5 * y)], -1).reshape(-1, 3)
    v = np.arange((cells + 1) ** 2).reshape(cells + 1, cells + 1)
    a, b, c, d = v[:-1, :-1], v[1:, :-1], v[:-1, 1:], v[1:, 1:]
    faces = np.concatenate([np.stack([a, b, d], -1), np.stack([a, d, c], -1)]).reshape(-1, 3)
    return pts.astype(np.float32), faces.astype(np.int32)


def state(mesh) -> tuple:
    bvh = mesh.bvh
    return (bvh._nodes.numpy().tobytes(), bvh._tree.items.numpy().tobytes(),
            mesh._faces.lowers.numpy().tobytes(), mesh._faces.edge_sum.numpy().tobytes())  # fmt: skip


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("recycled", [False, True])
def test_bad_meshes_raise_at_construction(device, recycled):
    recycle.clear()
    pts, faces = grid()
    points = wp.array(pts, dtype=wp.vec3, device=device)
    if recycled:  # face boxes (and a BVH build) of a collected mesh of as many faces
        wp.Mesh(points, wp.array(faces.ravel(), dtype=wp.int32, device=device))
        gc.collect()
        assert len(mesh_refit.FACE_BOXES) == 1
    bad_faces = faces.copy()
    bad_faces[5, 2] = len(pts) + 3
    with pytest.raises(KdslTypeError, match=f"out of range: {len(pts) + 3}"):
        wp.Mesh(points, wp.array(bad_faces.ravel(), dtype=wp.int32, device=device))
    nan_pts = pts.copy()
    nan_pts[7, 1] = np.nan
    indices = wp.array(faces.ravel(), dtype=wp.int32, device=device)
    with pytest.raises(KdslTypeError, match="point 7 is not finite"):
        wp.Mesh(wp.array(nan_pts, dtype=wp.vec3, device=device), indices)
    gc.collect()
    assert len(mesh_refit.FACE_BOXES) == 0  # refused meshes file nothing (and took the bin's)
    good = wp.Mesh(points, indices)
    got = state(good)
    del good
    gc.collect()
    again = wp.Mesh(points, indices)  # takes the face boxes just filed
    assert state(again) == got
    recycle.clear()
    assert state(wp.Mesh(points, indices)) == got  # a mesh of its own
    tri = pts[faces].astype(np.float64)
    edges = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).sum()
    np.testing.assert_allclose(again._faces.edge_sum.numpy()[0], edges, rtol=1e-5)


@pytest.mark.parametrize("device", DEVICES)
def test_a_bad_refit_keeps_the_bvh_and_the_edge_sum(device):
    pts, faces = grid()
    mesh = wp.Mesh(wp.array(pts, dtype=wp.vec3, device=device),
                   wp.array(faces, dtype=wp.int32, device=device))  # fmt: skip
    nodes, total = mesh.bvh._nodes.numpy().tobytes(), mesh._faces.edge_sum.numpy()[0]
    bad = pts.copy()
    bad[3] = np.inf
    mesh.points.assign(wp.array(bad, dtype=wp.vec3, device=device))
    for _ in range(2):  # (the second time through the refit's prepared steps)
        with pytest.raises(KdslTypeError, match="point 3 is not finite"):
            mesh.refit()
        assert mesh.bvh._nodes.numpy().tobytes() == nodes
        assert mesh._faces.edge_sum.numpy()[0] == total
    mesh.points.assign(wp.array(pts * 2, dtype=wp.vec3, device=device))
    mesh.refit()
    np.testing.assert_allclose(mesh._faces.edge_sum.numpy()[0], 2 * total, rtol=1e-6)


@pytest.mark.parametrize("leaf_size", [1, 4])
def test_first_run_with_the_merge_sort_is_the_sortkeys_tree(monkeypatch, leaf_size):
    rng = np.random.default_rng(leaf_size)
    n = 3000
    c = rng.random((n, 3)).astype(np.float32)
    lo = wp.array(c, dtype=wp.vec3)
    hi = wp.array(c + np.float32(0.01), dtype=wp.vec3)
    trees = []
    for kernels in (False, True):
        recycle.clear()
        monkeypatch.setattr(lbvh, "device_sort_on", lambda device, k=kernels: k)
        tree = lbvh.build_lbvh(lo, hi, leaf_size, None, 0, bottom_up=True, use_scan=False)
        trees.append([getattr(tree, k).numpy().tobytes() for k in ("skip", "first", "items")]
                     + [tree.nodes.numpy().tobytes()])  # fmt: skip
    assert trees[0] == trees[1]
