"""Mesh queries against a float64 brute force over every triangle, on interp and cpu."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from tests.geometry.mesh_reference import (
    closest_distances,
    closest_on_triangles,
    icosphere,
    ray_hits,
    winding_numbers,
)

BACKENDS = [
    "interp",
    "cpu",
    pytest.param("cuda", marks=pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")),
]
V3 = wp.vec3


def _device(backend: str) -> str:
    return "cuda" if backend == "cuda" else "cpu"


def _run(kernel, n, inputs, backend):
    wp.launch(kernel, dim=n, inputs=inputs, backend=backend, device=_device(backend))


def _mesh(pts, faces, backend, **kw):
    dev = _device(backend)
    return wp.Mesh(
        wp.array(pts, dtype=V3, device=dev), wp.array(faces, dtype=wp.int32, device=dev), **kw
    )


@wp.kernel
def closest_kernel(
    mesh: wp.uint64, xs: wp.array(dtype=V3), kind: int, cp: wp.array(dtype=V3),
    sign: wp.array(dtype=float), face: wp.array(dtype=int), found: wp.array(dtype=int),
):  # fmt: skip
    i = wp.tid()
    q = wp.MeshQueryPoint()
    if kind == 0:
        q = wp.mesh_query_point_no_sign(mesh, xs[i], 1.0e6)
    elif kind == 1:
        q = wp.mesh_query_point(mesh, xs[i], 1.0e6)
    elif kind == 2:
        q = wp.mesh_query_point_sign_normal(mesh, xs[i], 1.0e6)
    elif kind == 3:
        q = wp.mesh_query_point_sign_parity(mesh, xs[i], 1.0e6, 3)
    elif kind == 4:
        q = wp.mesh_query_point_sign_winding_number(mesh, xs[i], 1.0e6)
    else:
        q = wp.mesh_query_furthest_point_no_sign(mesh, xs[i], 0.0)
    found[i] = int(q.result)
    if q.result:
        cp[i] = wp.mesh_eval_position(mesh, q.face, q.u, q.v)
        sign[i] = q.sign
        face[i] = q.face


def _closest(mesh, xs, kind, backend):
    n = len(xs)
    dev = _device(backend)
    out = [wp.zeros(n, dtype=V3, device=dev), wp.zeros(n, dtype=float, device=dev),
           wp.full(n, -1, dtype=int, device=dev), wp.zeros(n, dtype=int, device=dev)]  # fmt: skip
    _run(closest_kernel, n, [mesh.id, wp.array(xs, dtype=V3, device=dev), kind, *out], backend)
    return [a.numpy() for a in out]


@pytest.fixture(scope="module")
def sphere():
    pts, faces = icosphere(2, bumps=0.1, seed=1)
    rng = np.random.default_rng(2)
    xs = rng.uniform(-1.5, 1.5, (48, 3)).astype(np.float32)
    return pts, faces, xs


@pytest.mark.parametrize("backend", BACKENDS)
def test_closest_point_and_signs_match_brute_force(backend, sphere):
    pts, faces, xs = sphere
    xs = xs[:12] if backend == "interp" else xs  # the interpreter is slow
    mesh = _mesh(pts, faces, backend, support_winding_number=True)
    ref = closest_distances(pts, faces, xs)
    inside = winding_numbers(pts, faces, xs) > 0.5
    for kind in range(5):
        cp, sign, face, found = _closest(mesh, xs, kind, backend)
        assert found.all()
        np.testing.assert_allclose(np.linalg.norm(cp - xs, axis=1), ref, rtol=1e-5, atol=1e-6)
        # the face's own closest point is where the query says
        tri = pts[faces[face]].astype(np.float64)
        assert np.all(face >= 0) and np.all(face < len(faces))
        assert np.all(
            np.linalg.norm(cp - tri.mean(1), axis=1)
            <= 2 * np.linalg.norm(tri[:, 0] - tri[:, 1], axis=1) + 1e-3
        )
        if kind == 0:
            assert np.all(sign == 0)
        else:
            np.testing.assert_array_equal(sign < 0, inside, err_msg=f"sign kind {kind}")


@pytest.mark.parametrize("backend", BACKENDS)
def test_furthest_point_matches_brute_force(backend, sphere):
    pts, faces, xs = sphere
    mesh = _mesh(pts, faces, backend)
    cp, _, _, found = _closest(mesh, xs[:16], 5, backend)
    ref = np.linalg.norm(pts[None].astype(np.float64) - xs[:16, None], axis=2).max(1)
    assert found.all()
    np.testing.assert_allclose(np.linalg.norm(cp - xs[:16], axis=1), ref, rtol=1e-5)


@wp.kernel
def ray_kernel(
    mesh: wp.uint64, starts: wp.array(dtype=V3), dirs: wp.array(dtype=V3), max_t: float,
    t: wp.array(dtype=float), face: wp.array(dtype=int), sign: wp.array(dtype=float),
    anyhit: wp.array(dtype=int), count: wp.array(dtype=int), pos: wp.array(dtype=V3),
):  # fmt: skip
    i = wp.tid()
    h = wp.mesh_query_ray(mesh, starts[i], dirs[i], max_t)
    if h.result:
        t[i] = h.t
        face[i] = h.face
        sign[i] = h.sign
        pos[i] = wp.mesh_eval_position(mesh, h.face, h.u, h.v)
    anyhit[i] = int(wp.mesh_query_ray_anyhit(mesh, starts[i], dirs[i], max_t))
    count[i] = wp.mesh_query_ray_count_intersections(mesh, starts[i], dirs[i])


def _rays(mesh, starts, dirs, backend, max_t=1.0e6):
    n = len(starts)
    dev = _device(backend)
    out = [wp.full(n, np.inf, dtype=float, device=dev), wp.full(n, -1, dtype=int, device=dev),
           wp.zeros(n, dtype=float, device=dev), wp.zeros(n, dtype=int, device=dev),
           wp.zeros(n, dtype=int, device=dev), wp.zeros(n, dtype=V3, device=dev)]  # fmt: skip
    ins = [wp.array(starts, dtype=V3, device=dev), wp.array(dirs, dtype=V3, device=dev), max_t]
    _run(ray_kernel, n, [mesh.id, *ins, *out], backend)
    return [a.numpy() for a in out]


@pytest.mark.parametrize("backend", BACKENDS)
def test_rays_match_brute_force(backend, sphere):
    pts, faces, xs = sphere
    mesh = _mesh(pts, faces, backend)
    rng = np.random.default_rng(3)
    dirs = rng.normal(size=xs.shape).astype(np.float32)
    t, face, sign, anyhit, count, pos = _rays(mesh, xs, dirs, backend)
    for i in range(len(xs)):
        ref = ray_hits(pts, faces, xs[i], dirs[i])
        hit = np.isfinite(ref)
        assert count[i] == hit.sum()
        assert anyhit[i] == hit.any()
        if hit.any():
            np.testing.assert_allclose(t[i], ref.min(), rtol=1e-5)
            assert ref[face[i]] <= ref.min() * (1 + 1e-5)
            np.testing.assert_allclose(pos[i], xs[i] + t[i] * dirs[i], atol=1e-5)
            n = np.cross(*(pts[faces[face[i]]][1:] - pts[faces[face[i]]][0]))
            assert np.sign(sign[i]) == -np.sign(np.dot(n, dirs[i]))  # > 0: the front
        else:
            assert face[i] == -1
    # max_t is strict and in multiples of dir's length
    _, _, _, anyhit2, _, _ = _rays(mesh, xs, dirs, backend, max_t=0.5)
    ref_first = np.array([ray_hits(pts, faces, xs[i], dirs[i]).min() for i in range(len(xs))])
    clear = np.abs(ref_first - 0.5) > 1e-4
    np.testing.assert_array_equal(anyhit2[clear], (ref_first < 0.5)[clear])


@wp.kernel
def overlap_kernel(
    mesh: wp.uint64, lo: V3, hi: V3, center: V3, radius: float,
    in_box: wp.array(dtype=int), in_sphere: wp.array(dtype=int),
):  # fmt: skip
    q = wp.mesh_query_aabb(mesh, lo, hi)
    f = 0
    while wp.mesh_query_next(q, f):
        in_box[f] = in_box[f] + 1
    s = wp.mesh_query_sphere(mesh, center, radius)
    while wp.mesh_query_aabb_next(s, f):
        in_sphere[f] = in_sphere[f] + 1


@pytest.mark.parametrize("backend", BACKENDS)
def test_box_and_sphere_queries_match_brute_force(backend, sphere):
    pts, faces, _ = sphere
    mesh = _mesh(pts, faces, backend)
    dev = _device(backend)
    lo, hi, center, radius = (-0.3, 0.1, -1.0), (0.4, 0.9, 0.2), np.array([0.3, -0.2, 0.5]), 0.6
    in_box = wp.zeros(len(faces), dtype=int, device=dev)
    in_sphere = wp.zeros(len(faces), dtype=int, device=dev)
    _run(
        overlap_kernel,
        1,
        [mesh.id, V3(*lo), V3(*hi), V3(*center), radius, in_box, in_sphere],
        backend,
    )
    tri = pts[faces]
    box_ref = np.all((tri.min(1) <= hi) & (tri.max(1) >= lo), axis=1)
    np.testing.assert_array_equal(in_box.numpy(), box_ref.astype(int))
    dist = np.linalg.norm(closest_on_triangles(center, tri.astype(np.float64)) - center, axis=1)
    clear = np.abs(dist - radius) > 1e-5
    np.testing.assert_array_equal(in_sphere.numpy()[clear], (dist <= radius)[clear].astype(int))
