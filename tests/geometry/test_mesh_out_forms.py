"""The older out-argument forms of the mesh queries (``mesh_query_point(mesh, x,
max_dist, sign, face, u, v) -> bool``, as the seeds use them) on interp, cpu and cuda:
each gives what its struct form gives, both match a float64 brute force, a miss leaves
the out-arguments untouched, and a kernel may mix out-argument forms with other queries
(the loop-carried values of one query must not leak into the next)."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from tests.geometry.mesh_reference import closest_distances, icosphere, ray_hits, winding_numbers
from tests.geometry.mesh_targets import BACKENDS, device_of

V3 = wp.vec3
#: The point queries by number: no_sign, point, sign_normal, sign_parity,
#: sign_winding_number, furthest_point_no_sign.
KINDS = range(6)
UNTOUCHED = -7


@wp.kernel
def point_forms(
    mesh: wp.uint64, xs: wp.array(dtype=V3), kind: int, max_dist: float,
    outs: wp.array2d(dtype=float), structs: wp.array2d(dtype=float),
):  # fmt: skip
    i = wp.tid()
    x = xs[i]
    sign = float(UNTOUCHED)
    face = int(UNTOUCHED)
    u = float(UNTOUCHED)
    v = float(UNTOUCHED)
    ok = False
    q = wp.MeshQueryPoint()
    if kind == 0:
        ok = wp.mesh_query_point_no_sign(mesh, x, max_dist, face, u, v)
        q = wp.mesh_query_point_no_sign(mesh, x, max_dist)
    elif kind == 1:
        ok = wp.mesh_query_point(mesh, x, max_dist, sign, face, u, v)
        q = wp.mesh_query_point(mesh, x, max_dist)
    elif kind == 2:
        ok = wp.mesh_query_point_sign_normal(mesh, x, max_dist, sign, face, u, v, epsilon=1.0e-3)
        q = wp.mesh_query_point_sign_normal(mesh, x, max_dist)
    elif kind == 3:
        ok = wp.mesh_query_point_sign_parity(mesh, x, max_dist, sign, face, u, v, n_sample=3)
        q = wp.mesh_query_point_sign_parity(mesh, x, max_dist, 3, 0.1)
    elif kind == 4:
        ok = wp.mesh_query_point_sign_winding_number(mesh, x, max_dist, sign, face, u, v)
        q = wp.mesh_query_point_sign_winding_number(mesh, x, max_dist, accuracy=2.0, threshold=0.5)
    else:
        ok = wp.mesh_query_furthest_point_no_sign(mesh, x, max_dist, face, u, v)
        q = wp.mesh_query_furthest_point_no_sign(mesh, x, max_dist)
    outs[i, 0] = float(ok)
    outs[i, 1] = sign
    outs[i, 2] = float(face)
    outs[i, 3] = u
    outs[i, 4] = v
    structs[i, 0] = float(q.result)
    structs[i, 1] = q.sign
    structs[i, 2] = float(q.face)
    structs[i, 3] = q.u
    structs[i, 4] = q.v




@pytest.fixture(scope="module")
def sphere():
    pts, faces = icosphere(2, bumps=0.1, seed=4)
    xs = np.random.default_rng(5).uniform(-1.4, 1.4, (10, 3)).astype(np.float32)
    return pts, faces, xs


def _point_forms(mesh, xs, kind, max_dist, backend):
    dev = device_of(backend)
    n = len(xs)
    outs, structs = (wp.zeros((n, 5), dtype=float, device=dev) for _ in range(2))
    wp.launch(point_forms, dim=n, backend=backend, device=dev,
              inputs=[mesh.id, wp.array(xs, dtype=V3, device=dev), kind, max_dist, outs, structs])  # fmt: skip
    return outs.numpy(), structs.numpy()


def _position(pts, faces, face, u, v):
    tri = pts.astype(np.float64)[faces[face.astype(int)]]
    return u[:, None] * tri[:, 0] + v[:, None] * tri[:, 1] + (1 - u - v)[:, None] * tri[:, 2]


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("kind", KINDS)
def test_out_argument_forms_match_struct_forms_and_brute_force(backend, kind, sphere):
    pts, faces, xs = sphere
    dev = device_of(backend)
    mesh = wp.Mesh(wp.array(pts, dtype=V3, device=dev), wp.array(faces, dtype=wp.int32, device=dev),
                   support_winding_number=True)  # fmt: skip
    far = kind == 5
    outs, structs = _point_forms(mesh, xs, kind, 0.0 if far else 1.0e6, backend)
    assert outs[:, 0].all()
    np.testing.assert_array_equal(outs[:, 2], structs[:, 2])  # the same face
    np.testing.assert_allclose(outs[:, 3:], structs[:, 3:], atol=1e-6)
    dist = np.linalg.norm(_position(pts, faces, outs[:, 2], outs[:, 3], outs[:, 4]) - xs, axis=1)
    if far:
        ref = np.linalg.norm(pts[None].astype(np.float64) - xs[:, None], axis=2).max(1)
    else:
        ref = closest_distances(pts, faces, xs)
    np.testing.assert_allclose(dist, ref, rtol=1e-5, atol=1e-6)
    if kind in (0, 5):
        assert np.all(outs[:, 1] == UNTOUCHED)  # no sign argument: never written
    else:
        np.testing.assert_array_equal(outs[:, 1], structs[:, 1])
        inside = winding_numbers(pts, faces, xs) > 0.5
        np.testing.assert_array_equal(outs[:, 1] < 0, inside)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("kind", KINDS)
def test_a_miss_leaves_the_out_arguments_untouched(backend, kind, sphere):
    pts, faces, _ = sphere
    dev = device_of(backend)
    mesh = wp.Mesh(wp.array(pts, dtype=V3, device=dev), wp.array(faces, dtype=wp.int32, device=dev))
    xs = np.array([[5.0, 0.0, 0.0], [np.nan, 0.0, 0.0]], np.float32)
    # closest within 0.5 of (5, 0, 0): none; furthest beyond 100: none; NaN: nothing
    outs, structs = _point_forms(mesh, xs, kind, 100.0 if kind == 5 else 0.5, backend)
    np.testing.assert_array_equal(outs[:, 0], 0)
    np.testing.assert_array_equal(outs[:, 1:], UNTOUCHED)
    np.testing.assert_array_equal(structs, 0)  # result False, face 0, u = v = sign = 0


@wp.kernel
def ray_forms(
    mesh: wp.uint64, starts: wp.array(dtype=V3), dirs: wp.array(dtype=V3),
    outs: wp.array2d(dtype=float), normals: wp.array(dtype=V3), count: wp.array(dtype=int),
    anyhit: wp.array(dtype=int), closest: wp.array(dtype=float),
):  # fmt: skip
    i = wp.tid()
    t = float(UNTOUCHED)
    u = float(UNTOUCHED)
    v = float(UNTOUCHED)
    sign = float(UNTOUCHED)
    normal = wp.vec3(float(UNTOUCHED))
    face = int(UNTOUCHED)
    ok = wp.mesh_query_ray(mesh, starts[i], dirs[i], 1.0e6, t, u, v, sign, normal, face, root=-1)
    outs[i, 0] = float(ok)
    outs[i, 1] = t
    outs[i, 2] = u
    outs[i, 3] = v
    outs[i, 4] = sign
    outs[i, 5] = float(face)
    normals[i] = normal
    # more queries in the same kernel, after the out-argument form
    count[i] = wp.mesh_query_ray_count_intersections(mesh, starts[i], dirs[i])
    anyhit[i] = int(wp.mesh_query_ray_anyhit(mesh, starts[i], dirs[i], max_t=1.0e6))
    q = wp.mesh_query_point_no_sign(mesh, starts[i], 1.0e6)
    closest[i] = wp.length(wp.mesh_eval_position(mesh, q.face, q.u, q.v) - starts[i])


@pytest.mark.parametrize("backend", BACKENDS)
def test_ray_out_form_then_more_queries_in_one_kernel(backend, sphere):
    pts, faces, xs = sphere
    dev = device_of(backend)
    mesh = wp.Mesh(wp.array(pts, dtype=V3, device=dev), wp.array(faces, dtype=wp.int32, device=dev))
    rng = np.random.default_rng(6)
    starts = np.concatenate([xs, [[5.0, 5.0, 5.0]]]).astype(np.float32)
    dirs = np.concatenate([rng.normal(size=xs.shape), [[1.0, 0.0, 0.0]]]).astype(np.float32)
    n = len(starts)
    outs = wp.zeros((n, 6), dtype=float, device=dev)
    normals = wp.zeros(n, dtype=V3, device=dev)
    count, anyhit = (wp.zeros(n, dtype=int, device=dev) for _ in range(2))
    closest = wp.zeros(n, dtype=float, device=dev)
    wp.launch(ray_forms, dim=n, backend=backend, device=dev,
              inputs=[mesh.id, wp.array(starts, dtype=V3, device=dev),
                      wp.array(dirs, dtype=V3, device=dev), outs, normals, count, anyhit,
                      closest])  # fmt: skip
    outs, normals = outs.numpy(), normals.numpy()
    for i in range(n):
        ref = ray_hits(pts, faces, starts[i], dirs[i])
        hit = np.isfinite(ref)
        assert count.numpy()[i] == hit.sum() and anyhit.numpy()[i] == hit.any()
        if not hit.any():
            assert outs[i, 0] == 0 and np.all(outs[i, 1:] == UNTOUCHED)
            assert np.all(normals[i] == UNTOUCHED)
            continue
        assert outs[i, 0] == 1
        np.testing.assert_allclose(outs[i, 1], ref.min(), rtol=1e-5)
        f = int(outs[i, 5])
        tri = pts.astype(np.float64)[faces[f]]
        n_ref = np.cross(tri[1] - tri[0], tri[2] - tri[0])
        n_ref /= np.linalg.norm(n_ref)
        np.testing.assert_allclose(normals[i], n_ref, atol=1e-5)
        assert np.sign(outs[i, 4]) == -np.sign(np.dot(n_ref, dirs[i]))
        hit_point = outs[i, 2] * tri[0] + outs[i, 3] * tri[1] + (1 - outs[i, 2] - outs[i, 3]) * tri[2]
        np.testing.assert_allclose(hit_point, starts[i] + outs[i, 1] * dirs[i], atol=1e-5)
    np.testing.assert_allclose(closest.numpy(), closest_distances(pts, faces, starts), rtol=1e-5)
