"""``kdsl.Mesh`` against warp-lang's ``warp.Mesh`` on the CPU: the same mesh and queries
(one kernel source compiled by both) give the same faces, barycentrics, signs, hits
and distances within float32 rounding, wherever Warp's answer does not depend on its
tie-breaking (two faces at the same distance, a ray through a shared edge)."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from tests.geometry.mesh_reference import closest_on_triangles, icosphere
from tests.warp_peer import import_warp_cpu

warp = import_warp_cpu()

#: Distances and ray parameters closer than this are ties in float32.
TIE = 1e-5


def _kernels(m):
    """The queries written once against module ``m`` (kdsl or warp)."""

    @m.kernel
    def points(mesh: m.uint64, xs: m.array(dtype=m.vec3), kind: int,
               face: m.array(dtype=m.int32), uvs: m.array(dtype=m.vec3)):  # fmt: skip
        i = m.tid()
        x = xs[i]
        q = m.mesh_query_point_no_sign(mesh, x, 10.0)
        if kind == 1:
            q = m.mesh_query_point_sign_normal(mesh, x, 10.0)
        elif kind == 2:
            q = m.mesh_query_point_sign_winding_number(mesh, x, 10.0)
        elif kind == 3:
            q = m.mesh_query_furthest_point_no_sign(mesh, x, 0.0)
        face[i] = -1
        if q.result:
            face[i] = q.face
            uvs[i] = m.vec3(q.u, q.v, q.sign)

    @m.kernel
    def rays(mesh: m.uint64, start: m.array(dtype=m.vec3), d: m.array(dtype=m.vec3),
             face: m.array(dtype=m.int32), tuvs: m.array(dtype=m.vec4),
             normal: m.array(dtype=m.vec3), counts: m.array(dtype=m.vec2i)):  # fmt: skip
        i = m.tid()
        q = m.mesh_query_ray(mesh, start[i], d[i], 1.0e6)
        face[i] = -1
        if q.result:
            face[i] = q.face
            tuvs[i] = m.vec4(q.t, q.u, q.v, q.sign)
            normal[i] = q.normal
        anyhit = 0
        if m.mesh_query_ray_anyhit(mesh, start[i], d[i], 1.0e6):
            anyhit = 1
        counts[i] = m.vec2i(anyhit, m.mesh_query_ray_count_intersections(mesh, start[i], d[i]))

    return points, rays


@pytest.fixture(scope="module")
def scene():
    pts, faces = icosphere(3, bumps=0.05, seed=3)
    rng = np.random.default_rng(4)
    n = 400
    xs = rng.uniform(-1.4, 1.4, (n, 3)).astype(np.float32)
    starts = rng.uniform(-1.4, 1.4, (n, 3)).astype(np.float32)
    dirs = rng.normal(size=(n, 3))
    dirs = (dirs / np.linalg.norm(dirs, axis=1, keepdims=True)).astype(np.float32)
    return pts, faces, xs, starts, dirs


def _answers(m, scene):
    pts, faces, xs, starts, dirs = scene
    points, rays = _kernels(m)
    n = len(xs)

    def v3(a):
        return m.array(a, dtype=m.vec3, device="cpu")

    mesh = m.Mesh(v3(pts), m.array(faces.reshape(-1), dtype=m.int32, device="cpu"),
                  support_winding_number=True)  # fmt: skip
    out = {}
    for kind in range(4):
        face = m.zeros(n, dtype=m.int32, device="cpu")
        uvs = m.zeros(n, dtype=m.vec3, device="cpu")
        m.launch(points, dim=n, inputs=[mesh.id, v3(xs), kind, face, uvs], device="cpu")
        out[kind] = (face.numpy(), uvs.numpy())
    face = m.zeros(n, dtype=m.int32, device="cpu")
    tuvs = m.zeros(n, dtype=m.vec4, device="cpu")
    normal = m.zeros(n, dtype=m.vec3, device="cpu")
    counts = m.zeros(n, dtype=m.vec2i, device="cpu")
    m.launch(rays, dim=n, inputs=[mesh.id, v3(starts), v3(dirs), face, tuvs, normal, counts],
             device="cpu")  # fmt: skip
    out["ray"] = (face.numpy(), tuvs.numpy(), normal.numpy(), counts.numpy())
    return out


@pytest.fixture(scope="module")
def both(scene):
    return _answers(wp, scene), _answers(warp, scene)


def _distances(pts, faces, x, face_ids):
    """Float64 distances from ``x`` to the faces ``face_ids``."""
    tri = pts[faces[face_ids]].astype(np.float64)
    return np.linalg.norm(closest_on_triangles(x.astype(np.float64), tri) - x, axis=1)


@pytest.mark.parametrize("kind", [0, 1, 2])
def test_closest_point_matches_warp(both, scene, kind):
    pts, faces, xs, _, _ = scene
    (kf, kuv), (wf, wuv) = both[0][kind], both[1][kind]
    assert (kf >= 0).all() and (wf >= 0).all()
    same = kf == wf
    # Elsewhere a tie (the closest point is a vertex or an edge several faces share;
    # kdsl takes the lowest face, Warp the first it visits): both faces are as close.
    for i in np.flatnonzero(~same):
        d = _distances(pts, faces, xs[i], np.array([kf[i], wf[i]]))
        assert abs(d[0] - d[1]) < TIE, (i, kf[i], wf[i], d)
    np.testing.assert_allclose(kuv[same, :2], wuv[same, :2], atol=1e-4)
    if kind:
        # inside (< 0) or outside (> 0) agree away from the surface
        tri = pts[faces[kf]].astype(np.float64)
        near = np.array([
            np.linalg.norm(closest_on_triangles(xs[i].astype(np.float64), tri[i : i + 1]) - xs[i])
            for i in range(len(xs))
        ]) < 1e-3  # fmt: skip
        assert ((kuv[:, 2] < 0) == (wuv[:, 2] < 0))[~near].all()


def test_furthest_point_matches_warp(both, scene):
    pts, faces, xs, _, _ = scene
    (kf, kuv), (wf, wuv) = both[0][3], both[1][3]
    assert (kf >= 0).all() and (wf >= 0).all()
    # the furthest vertex of the chosen faces is equally far
    kd = np.linalg.norm(pts[faces[kf]] - xs[:, None], axis=2).max(axis=1)
    wd = np.linalg.norm(pts[faces[wf]] - xs[:, None], axis=2).max(axis=1)
    np.testing.assert_allclose(kd, wd, rtol=1e-6)


def test_rays_match_warp(both):
    kf, kt, kn, kc = both[0]["ray"]
    wf, wt, wn, wc = both[1]["ray"]
    hit = kf >= 0
    assert 0.2 < hit.mean() < 1.0  # some rays miss, most hit
    np.testing.assert_array_equal(hit, wf >= 0)
    np.testing.assert_allclose(kt[hit, 0], wt[hit, 0], rtol=TIE, atol=TIE)
    same = hit & (kf == wf)
    assert same.sum() == hit.sum()  # random rays cross no shared edge
    np.testing.assert_allclose(kt[same, 1:3], wt[same, 1:3], atol=1e-4)
    np.testing.assert_array_equal(np.sign(kt[same, 3]), np.sign(wt[same, 3]))
    np.testing.assert_allclose(kn[same], wn[same], atol=1e-5)
    np.testing.assert_array_equal(kc, wc)  # any hit and the number of crossings
