"""A mesh's vertex copy in BVH item order (``MeshRecord.tri``, written by
``kdsl.geometry.mesh_tree_points``): it holds ``points[indices[3 items[k] + j]]`` at
``3 k + j`` after construction, after the points move in place and ``refit()``, after
``mesh.points`` is assigned, and after ``mesh.bvh.rebuild()`` reorders the items; and
the queries that read it find the brute force's answers after each of those."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.stdlib.bvh import BvhRecord
from kdsl.stdlib.mesh import MeshRecord
from tests.geometry.mesh_reference import closest_distances, icosphere, ray_hits
from tests.geometry.test_mesh_walks import BACKENDS, V3


@wp.kernel
def copy_kernel(mesh: wp.uint64, expected: wp.array(dtype=V3), tri: wp.array(dtype=V3)):
    # tri[i]: the copy as kernels read it; expected[i]: the corner it must hold.
    i = wp.tid()
    rec = wp.object_record(mesh, MeshRecord)
    bvh = wp.object_record(rec.bvh, BvhRecord)
    k = i // 3
    tri[i] = rec.tri[i]
    expected[i] = rec.points[rec.indices[bvh.items[k] * 3 + i % 3]]


@wp.kernel
def query_kernel(
    mesh: wp.uint64, xs: wp.array(dtype=V3), dirs: wp.array(dtype=V3),
    dist: wp.array(dtype=float), t: wp.array(dtype=float), anyhit: wp.array(dtype=int),
):  # fmt: skip
    i = wp.tid()
    q = wp.mesh_query_point_no_sign(mesh, xs[i], 1.0e6)
    dist[i] = wp.length(wp.mesh_eval_position(mesh, q.face, q.u, q.v) - xs[i])
    h = wp.mesh_query_ray(mesh, xs[i], dirs[i], 1.0e6)
    t[i] = -1.0
    if h.result:
        t[i] = h.t
    anyhit[i] = int(wp.mesh_query_ray_anyhit(mesh, xs[i], dirs[i], 1.0e6))


@wp.kernel
def move_kernel(points: wp.array(dtype=V3), shift: V3, scale: float):
    i = wp.tid()
    points[i] = points[i] * scale + shift


def _device(backend: str) -> str:
    return "cuda" if backend == "cuda" else "cpu"


def _check_copy(mesh, backend: str) -> None:
    n = mesh.indices.shape[0]  # three corners a face
    dev = _device(backend)
    expected, tri = (wp.zeros(n, dtype=V3, device=dev) for _ in range(2))
    wp.launch(copy_kernel, dim=n, inputs=[mesh.id, expected, tri], backend=backend, device=dev)
    np.testing.assert_array_equal(tri.numpy(), expected.numpy())


def _check_queries(mesh, pts: np.ndarray, faces: np.ndarray, backend: str) -> None:
    """Closest points, closest and any ray hits from points around the mesh's current
    shape against the float64 brute force over ``pts``."""
    dev = _device(backend)
    rng = np.random.default_rng(3)
    n = 8 if backend == "interp" else 32
    centre = pts.mean(axis=0)
    xs = (centre + rng.uniform(-1.5, 1.5, (n, 3))).astype(np.float32)
    dirs = rng.normal(size=(n, 3)).astype(np.float32)
    dist, t = (wp.zeros(n, dtype=float, device=dev) for _ in range(2))
    anyhit = wp.zeros(n, dtype=int, device=dev)
    wp.launch(query_kernel, dim=n, inputs=[mesh.id, wp.array(xs, dtype=V3, device=dev),
                                           wp.array(dirs, dtype=V3, device=dev), dist, t, anyhit],
              backend=backend, device=dev)  # fmt: skip
    np.testing.assert_allclose(dist.numpy(), closest_distances(pts, faces, xs), rtol=1e-5,
                               atol=1e-6)  # fmt: skip
    for i in range(n):
        ref = ray_hits(pts, faces, xs[i], dirs[i])
        hit = np.isfinite(ref)
        assert anyhit.numpy()[i] == hit.any(), i
        if hit.any():
            np.testing.assert_allclose(t.numpy()[i], ref.min(), rtol=1e-5)
        else:
            assert t.numpy()[i] == -1.0, i


@pytest.mark.parametrize("backend", BACKENDS)
def test_vertex_copy_follows_refit_point_writes_and_rebuild(backend):
    pts, faces = icosphere(2, bumps=0.05, seed=7)
    dev = _device(backend)
    points = wp.array(pts, dtype=V3, device=dev)
    mesh = wp.Mesh(points, wp.array(faces, dtype=wp.int32, device=dev), bvh_constructor="lbvh")
    _check_copy(mesh, backend)
    _check_queries(mesh, pts, faces, backend)

    # moved in place by a kernel, then refit
    shift, scale = wp.vec3(0.5, -0.25, 2.0), 1.5
    wp.launch(move_kernel, dim=len(pts), inputs=[points, shift, scale], device=dev)
    mesh.refit()
    moved = points.numpy()
    np.testing.assert_allclose(moved, pts * scale + np.array([0.5, -0.25, 2.0]), rtol=1e-6)
    _check_copy(mesh, backend)
    _check_queries(mesh, moved, faces, backend)

    # a new points array assigned (refits by itself)
    rng = np.random.default_rng(8)
    wobbled = (pts * (1.0 + 0.1 * rng.uniform(-1, 1, (len(pts), 1)))).astype(np.float32)
    mesh.points = wp.array(wobbled, dtype=V3, device=dev)
    _check_copy(mesh, backend)
    _check_queries(mesh, wobbled, faces, backend)

    # rebuilt with another constructor: the items come in another order
    before = mesh.bvh.item_order.numpy().copy()
    mesh.bvh.rebuild("median")
    assert not np.array_equal(before, mesh.bvh.item_order.numpy())
    _check_copy(mesh, backend)
    _check_queries(mesh, wobbled, faces, backend)

    # and rebuilt in place by the same constructor after another move
    mesh.bvh.rebuild("lbvh")
    wp.launch(move_kernel, dim=len(pts), inputs=[mesh.points, wp.vec3(0.0), 0.5], device=dev)
    mesh.refit()
    mesh.bvh.rebuild()
    _check_copy(mesh, backend)
    _check_queries(mesh, mesh.points.numpy(), faces, backend)


def test_empty_mesh_has_an_empty_copy():
    mesh = wp.Mesh(wp.zeros(0, dtype=V3), wp.zeros(0, dtype=wp.int32))
    mesh.refit()
    mesh.bvh.rebuild()
    out = wp.zeros(1, dtype=int)
    wp.launch(query_count_kernel, dim=1, inputs=[mesh.id, out])
    assert out.numpy()[0] == 0


@wp.kernel
def query_count_kernel(mesh: wp.uint64, out: wp.array(dtype=int)):
    rec = wp.object_record(mesh, MeshRecord)
    q = wp.mesh_query_point_no_sign(mesh, wp.vec3(0.0), 1.0e6)
    out[0] = rec.tri.shape[0] + int(q.result)
