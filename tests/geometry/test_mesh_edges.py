"""Mesh edge cases, the out-argument forms (the seed's ``project`` kernel), gradients,
accessors and bad input. The edge cases (docs/geometry.md, "Edge cases") run on
interp, cpu and cuda."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslTypeError

BACKENDS = ["interp", "cpu"]
#: The edge-case tests also run on a GPU.
ALL_BACKENDS = [
    *BACKENDS,
    pytest.param("cuda", marks=pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")),
]
V3 = wp.vec3
# Two triangles sharing the edge (1, 2) in the plane z = 0, and a sliver.
PTS = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [2, 2, 2], [3, 3, 3]], np.float32)
FACES = np.array([[0, 1, 2], [1, 3, 2], [4, 5, 5]], np.int32)


def _dev(backend: str) -> str:
    return "cuda" if backend == "cuda" else "cpu"


def _mesh(pts=PTS, faces=FACES, device="cpu", **kw):
    return wp.Mesh(wp.array(pts, dtype=V3, device=device),
                   wp.array(faces, dtype=wp.int32, device=device), **kw)  # fmt: skip


# The seed's kernel, unchanged (Warp's blog post, "Meshes").
@wp.kernel
def project(
    positions: wp.array(dtype=wp.vec3),
    mesh: wp.uint64,
    output_pos: wp.array(dtype=wp.vec3),
    output_face: wp.array(dtype=int),
):
    tid = wp.tid()
    x = wp.load(positions, tid)
    face_index = 0
    face_u = 0.0
    face_v = 0.0
    sign = 0.0
    max_dist = 2.0
    if wp.mesh_query_point(mesh, x, max_dist, sign, face_index, face_u, face_v):
        p = wp.mesh_eval_position(mesh, face_index, face_u, face_v)
        output_pos[tid] = p
        output_face[tid] = face_index


def _project(mesh, xs, backend):
    n, dev = len(xs), _dev(backend)
    pos = wp.full(n, V3(-7.0, -7.0, -7.0), dtype=V3, device=dev)
    face = wp.full(n, -7, dtype=int, device=dev)
    wp.launch(project, dim=n, inputs=[wp.array(xs, dtype=V3, device=dev), mesh.id, pos, face],
              backend=backend, device=dev)  # fmt: skip
    return pos.numpy(), face.numpy()


@pytest.mark.parametrize("backend", ALL_BACKENDS)
def test_seed_project_kernel_and_ties(backend):
    xs = np.array(
        [
            [0.2, 0.2, 0.5],  # above face 0
            [1.0, 0.0, 0.0],  # on vertex 1, shared by faces 0 and 1: the lowest face
            [0.5, 0.5, 0.0],  # on the shared edge: the lowest face
            [0.5, 0.5, -1.0],  # below the shared edge, same distance to both: face 0
            [9.0, 9.0, 9.0],  # beyond max_dist: outputs untouched
            [np.nan, 0.0, 0.0],  # NaN: no result, outputs untouched
            [1.5, 1.5, 1.8],  # nearer the sliver (left out) than face 1 corner: face 1
        ],
        np.float32,
    )
    pos, face = _project(_mesh(device=_dev(backend)), xs, backend)
    np.testing.assert_array_equal(face, [0, 0, 0, 0, -7, -7, 1])
    np.testing.assert_allclose(
        pos[:4], [[0.2, 0.2, 0], [1, 0, 0], [0.5, 0.5, 0], [0.5, 0.5, 0]], atol=1e-6
    )
    assert np.all(pos[4:6] == -7.0)


@wp.kernel
def rays_kernel(
    mesh: wp.uint64, starts: wp.array(dtype=V3), dirs: wp.array(dtype=V3),
    out_face: wp.array(dtype=int), out_t: wp.array(dtype=float),
):  # fmt: skip
    i = wp.tid()
    hit_t = 0.0
    hit_u = 0.0
    hit_v = 0.0
    hit_sign = 0.0
    hit_normal = wp.vec3()
    hit_face = -1
    if wp.mesh_query_ray(
        mesh, starts[i], dirs[i], 1.0e6, hit_t, hit_u, hit_v, hit_sign, hit_normal, hit_face
    ):
        out_face[i] = hit_face
        out_t[i] = hit_t


@wp.kernel
def count_kernel(
    mesh: wp.uint64,
    starts: wp.array(dtype=V3),
    dirs: wp.array(dtype=V3),
    count: wp.array(dtype=int),
):
    i = wp.tid()
    count[i] = wp.mesh_query_ray_count_intersections(mesh, starts[i], dirs[i])


@pytest.mark.parametrize("backend", ALL_BACKENDS)
def test_ray_edge_cases(backend):
    starts = np.array(
        [
            [0.5, 0.5, 1.0],
            [1.0, 0.0, 1.0],
            [-1.0, 0.5, 0.0],
            [0.2, 0.2, 1.0],
            [np.nan, 0, 1],
            [0.2, 0.2, 0.0],
        ],
        np.float32,
    )
    dirs = np.array(
        [[0, 0, -1], [0, 0, -1], [1, 0, 0], [0, 0, 1], [0, 0, -1], [0, 0, -1]], np.float32
    )
    n, dev = len(starts), _dev(backend)
    face, t, count = (
        wp.full(n, -1, dtype=int, device=dev),
        wp.full(n, -1.0, dtype=float, device=dev),
        wp.zeros(n, dtype=int, device=dev),
    )
    mesh = _mesh(device=dev)
    ins = [wp.array(starts, dtype=V3, device=dev), wp.array(dirs, dtype=V3, device=dev)]
    wp.launch(rays_kernel, dim=n, inputs=[mesh.id, *ins, face, t], backend=backend, device=dev)
    wp.launch(count_kernel, dim=n, inputs=[mesh.id, *ins, count], backend=backend, device=dev)
    # through the shared edge: both faces are hit at t = 1, the lowest wins; count sees both
    # (watertight); through a shared vertex likewise; parallel to the faces: a miss; away
    # from them: a miss; NaN: a miss; from on the face: t = 0
    np.testing.assert_array_equal(face.numpy(), [0, 0, -1, -1, -1, 0])
    np.testing.assert_allclose(t.numpy(), [1, 1, -1, -1, -1, 0])
    np.testing.assert_array_equal(count.numpy(), [2, 2, 0, 0, 0, 1])


@wp.kernel
def everything_kernel(mesh: wp.uint64, out: wp.array(dtype=int)):
    p = wp.vec3(0.0, 0.0, 0.0)
    out[0] = int(wp.mesh_query_point(mesh, p, 1.0e6).result)
    out[1] = int(wp.mesh_query_point_no_sign(mesh, p, 1.0e6).result)
    out[2] = int(wp.mesh_query_furthest_point_no_sign(mesh, p, 0.0).result)
    out[3] = int(wp.mesh_query_ray(mesh, p, wp.vec3(1.0, 0.0, 0.0), 1.0e6).result)
    out[4] = int(wp.mesh_query_ray_anyhit(mesh, p, wp.vec3(1.0, 0.0, 0.0), 1.0e6))
    out[5] = wp.mesh_query_ray_count_intersections(mesh, p, wp.vec3(1.0, 0.0, 0.0))
    q = wp.mesh_query_aabb(mesh, wp.vec3(-1.0), wp.vec3(1.0))
    f = 0
    out[6] = int(wp.mesh_query_next(q, f))
    out[7] = int(wp.mesh_query_point_sign_normal(mesh, p, 1.0e6).result)


@pytest.mark.parametrize("backend", ALL_BACKENDS)
def test_empty_mesh_finds_nothing(backend):
    dev = _dev(backend)
    mesh = wp.Mesh(wp.zeros(0, dtype=V3, device=dev), wp.zeros(0, dtype=wp.int32, device=dev))
    out = wp.full(8, 7, dtype=int, device=dev)
    wp.launch(everything_kernel, dim=1, inputs=[mesh.id, out], backend=backend, device=dev)
    np.testing.assert_array_equal(out.numpy(), 0)


@wp.kernel
def degenerate_kernel(mesh: wp.uint64, radius: wp.array(dtype=float), centers: wp.array(dtype=V3),
                      hits: wp.array2d(dtype=int), ray: wp.array(dtype=float)):  # fmt: skip
    i = wp.tid()
    q = wp.mesh_query_sphere(mesh, centers[i], radius[i])
    f = 0
    while wp.mesh_query_next(q, f):
        hits[i, f] = 1
    if i == 0:  # down through the zero-area face (a segment) onto face 0
        start = wp.vec3(0.5, 0.2, 10.0)
        down = wp.vec3(0.0, 0.0, -1.0)
        h = wp.mesh_query_ray(mesh, start, down, 1.0e6)
        ray[0] = float(h.face)
        ray[1] = h.t
        ray[2] = float(wp.mesh_query_ray_count_intersections(mesh, start, down))


@pytest.mark.parametrize("backend", ALL_BACKENDS)
def test_degenerate_faces_and_negative_radius(backend):
    dev = _dev(backend)
    # face 2 has coincident vertices (a segment), face 3 collinear ones, both zero-area
    pts = np.concatenate([PTS, [[0, 0.2, 5], [1, 0.2, 5], [2, 0.2, 5]]]).astype(np.float32)
    faces = np.concatenate([FACES, [[6, 7, 8]]]).astype(np.int32)
    mesh = _mesh(pts, faces, device=dev)
    centers = np.array([[0.0, 0.0, 0.0], [2.5, 2.5, 2.6], [2.5, 2.5, 2.6], [1.5, 0.2, 5.05]],
                       np.float32)  # fmt: skip
    radius = np.array([-1.0, 0.1, 0.05, 0.1], np.float32)
    hits = wp.zeros((4, len(faces)), dtype=int, device=dev)
    ray = wp.zeros(3, dtype=float, device=dev)
    wp.launch(degenerate_kernel, dim=4, backend=backend, device=dev,
              inputs=[mesh.id, wp.array(radius, device=dev),
                      wp.array(centers, dtype=V3, device=dev), hits, ray])  # fmt: skip
    # a negative radius is 0 (the centre is face 0's vertex; face 1, 0.71 away, is not
    # within 1 = |radius|); a zero-area face counts by its
    # longest edge (the segment (2,2,2)-(3,3,3) is 0.082 from the second centre)
    np.testing.assert_array_equal(hits.numpy(), [[1, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 0],
                                                 [0, 0, 0, 1]])  # fmt: skip
    # a ray through a zero-area face does not hit it (its determinant is 0)
    np.testing.assert_allclose(ray.numpy(), [0, 10, 1])


@wp.kernel
def accessors_kernel(mesh: wp.uint64, v: wp.array(dtype=V3), i: wp.array(dtype=int)):
    v[0] = wp.mesh_get_point(mesh, 4)
    v[1] = wp.mesh_get_velocity(mesh, 4)
    v[2] = wp.mesh_eval_velocity(mesh, 1, 0.5, 0.25)
    v[3] = wp.mesh_eval_face_normal(mesh, 1)
    v[4] = wp.mesh_get(mesh).points[3]
    i[0] = wp.mesh_get_index(mesh, 4)
    i[1] = wp.mesh_get_group_root(mesh, 1)
    i[2] = wp.mesh_get_group_root(mesh, 9)
    q = wp.bvh_query_aabb(wp.mesh_get_bvh(mesh), wp.vec3(2.4, 2.4, 2.4), wp.vec3(2.6, 2.6, 2.6))
    f = -1
    wp.bvh_query_next(q, f)
    i[3] = f


@pytest.mark.parametrize("backend", BACKENDS)
def test_accessors_velocities_groups(backend):
    vel = PTS * 2.0
    mesh = _mesh(velocities=wp.array(vel, dtype=V3), groups=wp.array([0, 1, 1], dtype=wp.int32))
    v, i = wp.zeros(5, dtype=V3), wp.zeros(4, dtype=int)
    wp.launch(accessors_kernel, dim=1, inputs=[mesh.id, v, i], backend=backend)
    v = v.numpy()
    np.testing.assert_allclose(v[0], PTS[3])
    np.testing.assert_allclose(v[1], vel[3])
    np.testing.assert_allclose(v[2], 0.5 * vel[1] + 0.25 * vel[3] + 0.25 * vel[2])
    np.testing.assert_allclose(v[3], [0, 0, 1])
    np.testing.assert_allclose(v[4], PTS[3])
    i = i.numpy()
    assert i[0] == 3 and i[1] >= 0 and i[2] == -1 and i[3] == 2
    # a mesh without velocities gives zeros
    v2 = wp.zeros(5, dtype=V3)
    wp.launch(
        accessors_kernel, dim=1, inputs=[_mesh().id, v2, wp.zeros(4, dtype=int)], backend=backend
    )
    np.testing.assert_array_equal(v2.numpy()[1:3], 0)


@wp.kernel
def distance_kernel(mesh: wp.uint64, xs: wp.array(dtype=V3), out: wp.array(dtype=V3)):
    i = wp.tid()
    q = wp.mesh_query_point_no_sign(mesh, xs[i], 1.0e6)
    out[i] = wp.mesh_eval_position(mesh, q.face, q.u, q.v)


@pytest.mark.parametrize("backend", BACKENDS)
def test_closest_point_gradient_wrt_query_point(backend):
    # points over the face interior, beyond an edge and beyond a vertex
    xs0 = np.array(
        [[0.2, 0.3, 0.4], [0.6, -0.5, 0.3], [-0.4, -0.3, 0.2], [1.5, 0.7, -0.3]], np.float32
    )
    mesh = _mesh()
    w = np.array([[1.0, 2.0, 3.0]] * len(xs0), np.float32)

    def loss(xs_np):
        out = wp.zeros(len(xs0), dtype=V3)
        wp.launch(
            distance_kernel,
            dim=len(xs0),
            inputs=[mesh.id, wp.array(xs_np, dtype=V3), out],
            backend=backend,
        )
        return float((out.numpy().astype(np.float64) * w).sum())

    xs = wp.array(xs0, dtype=V3, requires_grad=True)
    out = wp.zeros(len(xs0), dtype=V3, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(distance_kernel, dim=len(xs0), inputs=[mesh.id, xs, out], backend=backend)
    tape.backward(grads={out: wp.array(w, dtype=V3)})
    g = xs.grad.numpy()
    h = 1e-3
    fd = np.zeros_like(g)
    for i in range(len(xs0)):
        for k in range(3):
            xp, xm = xs0.copy(), xs0.copy()
            xp[i, k] += h
            xm[i, k] -= h
            fd[i, k] = (loss(xp) - loss(xm)) / (2 * h)
    np.testing.assert_allclose(g, fd, atol=2e-2)
    assert np.abs(g).sum() > 1.0  # the gradient is not trivially zero


def test_refit_after_moving_points():
    mesh = _mesh()
    pos, _ = _project(mesh, np.array([[0.2, 0.2, 1.5]], np.float32), "cpu")
    np.testing.assert_allclose(pos[0], [0.2, 0.2, 0.0], atol=1e-6)
    mesh.points.assign(PTS + np.float32([0, 0, 1]))
    mesh.refit()
    pos, _ = _project(mesh, np.array([[0.2, 0.2, 1.5]], np.float32), "cpu")
    np.testing.assert_allclose(pos[0], [0.2, 0.2, 1.0], atol=1e-6)
    mesh.points = wp.array(PTS - np.float32([0, 0, 0.25]), dtype=V3)  # assigning refits
    pos, _ = _project(mesh, np.array([[0.2, 0.2, 1.5]], np.float32), "cpu")
    np.testing.assert_allclose(pos[0], [0.2, 0.2, -0.25], atol=1e-6)


def test_views_without_copies():
    pts2d = wp.array(PTS, dtype=wp.float32)  # (n, 3) float32 viewed as vec3
    idx2d = wp.array(FACES, dtype=wp.int32)  # (m, 3) flattened
    mesh = wp.Mesh(pts2d, idx2d)
    assert mesh.points.ptr == pts2d.ptr and mesh.indices.ptr == idx2d.ptr
    assert mesh.indices.shape == (9,)


def test_numpy_and_torch_memory_is_used_in_place():
    pts, faces = PTS.copy(), FACES.copy()
    mesh = wp.Mesh(wp.array(pts, copy=False), wp.array(faces, copy=False))  # (n, 3), (m, 3)
    assert mesh.points.ptr == pts.ctypes.data and mesh.indices.ptr == faces.ctypes.data
    torch = pytest.importorskip("torch")
    tp, tf = torch.from_numpy(PTS.copy()), torch.from_numpy(FACES.copy())
    mesh = wp.Mesh(wp.from_torch(tp), wp.from_torch(tf))
    assert mesh.points.ptr == tp.data_ptr() and mesh.indices.ptr == tf.data_ptr()
    tp[:, 2] += 1.0  # moved in place through torch, then refit: the mesh follows
    mesh.refit()
    pos, _ = _project(mesh, np.array([[0.2, 0.2, 1.5]], np.float32), "cpu")
    np.testing.assert_allclose(pos[0], [0.2, 0.2, 1.0], atol=1e-6)


@pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")
def test_cupy_memory_is_used_in_place():
    cp = pytest.importorskip("cupy")
    pts, faces = cp.asarray(PTS), cp.asarray(FACES)
    mesh = wp.Mesh(wp.from_dlpack(pts), wp.from_dlpack(faces))
    assert mesh.points.ptr == pts.data.ptr and mesh.indices.ptr == faces.data.ptr
    assert mesh.device == "cuda:0"
    pos, face = _project(mesh, np.array([[0.2, 0.2, 1.5]], np.float32), "cuda")
    np.testing.assert_allclose(pos[0], [0.2, 0.2, 0.0], atol=1e-6)
    assert face[0] == 0


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda: _mesh(faces=np.array([[0, 1, 6]], np.int32)), "out of range: 6"),
        (lambda: _mesh(faces=np.array([[0, -1, 2]], np.int32)), "out of range: -1"),
        (
            lambda: wp.Mesh(wp.array(PTS, dtype=V3), wp.array([0, 1, 2, 3], dtype=wp.int32)),
            "multiple of 3",
        ),
        (
            lambda: wp.Mesh(
                wp.array(PTS, dtype=V3), wp.array(np.zeros((2, 4), np.int32), dtype=wp.int32)
            ),
            r"\(faces, 3\)",
        ),
        (lambda: wp.Mesh(wp.array(PTS, dtype=V3), wp.array(FACES, dtype=wp.float32)), "int32"),
        (
            lambda: wp.Mesh(
                wp.array(PTS[:, :2], dtype=wp.float32), wp.array(FACES, dtype=wp.int32)
            ),
            "vec3",
        ),
        (lambda: wp.Mesh(PTS, wp.array(FACES, dtype=wp.int32)), "kdsl.array"),
        (
            lambda: _mesh(pts=np.where(PTS == 3, np.nan, PTS).astype(np.float32)),
            "point 5 is not finite",
        ),
        (lambda: _mesh(velocities=wp.zeros(2, dtype=V3)), "velocities must match"),
        (lambda: _mesh(groups=wp.zeros(2, dtype=wp.int32)), "one entry per face"),
    ],
)
def test_bad_input_is_a_clear_error(make, match):
    with pytest.raises(KdslTypeError, match=match):
        make()
