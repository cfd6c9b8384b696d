"""The CPU mesh's 4-wide tree (``kdsl.geometry.wide_tree``) and the closest-point walk
over it (``kdsl.stdlib.mesh_wide``): its layout covers every face once under boxes that
hold them, it follows refits and rebuilds, and its answers are the binary walk's, face
for face (lowest index among ties, slivers left out, NaN points), and the float64 brute
force's, on the interpreter and the cpu backend. A mesh on a GPU keeps no wide tree
(``WIDE_TREE``); the cuda variant checks that its answers are unchanged."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
import kdsl.geometry.wide_tree as wide_tree
import kdsl.stdlib.mesh_wide as mesh_wide
from kdsl.stdlib.mesh import MeshRecord
from tests.geometry.mesh_reference import closest_distances, icosphere

V3 = wp.vec3
HOST_BACKENDS = ["interp", "cpu"]


@wp.kernel
def point_kernel(mesh: wp.uint64, xs: wp.array(dtype=V3), bound: float, far: int,
                 face: wp.array(dtype=int), dist: wp.array(dtype=float)):  # fmt: skip
    # The closest point within ``bound`` (far == 0) or the furthest beyond it: the
    # face and its point's distance, or -1 for both.
    i = wp.tid()
    q = wp.MeshQueryPoint()
    if far != 0:
        q = wp.mesh_query_furthest_point_no_sign(mesh, xs[i], bound)
    else:
        q = wp.mesh_query_point_no_sign(mesh, xs[i], bound)
    face[i] = -1
    dist[i] = -1.0
    if q.result:
        face[i] = q.face
        dist[i] = wp.length(wp.mesh_eval_position(mesh, q.face, q.u, q.v) - xs[i])


@wp.kernel
def signed_kernel(mesh: wp.uint64, xs: wp.array(dtype=V3), sign: wp.array(dtype=float)):
    i = wp.tid()
    sign[i] = wp.mesh_query_point(mesh, xs[i], 1.0e6).sign


@wp.kernel
def wide_id_kernel(wide: wp.uint64, xs: wp.array(dtype=V3), face: wp.array(dtype=int)):
    i = wp.tid()
    face[i] = mesh_wide.wide_closest_face(wide, xs[i], 1.0e6)


def _mesh(pts, faces, wide: bool, monkeypatch, **kw):
    """A cpu mesh with (or without) its 4-wide tree."""
    monkeypatch.setitem(wide_tree.WIDE_TREE, "cpu", wide)
    return wp.Mesh(wp.array(pts, dtype=V3), wp.array(faces, dtype=wp.int32), **kw)


def _query(mesh, xs, backend, bound, far, device="cpu"):
    n = len(xs)
    face, dist = wp.zeros(n, dtype=int, device=device), wp.zeros(n, dtype=float, device=device)
    wp.launch(point_kernel, dim=n, backend=backend, device=device,
              inputs=[mesh.id, wp.array(xs, dtype=V3, device=device), bound, far, face, dist])  # fmt: skip
    return face.numpy(), dist.numpy()


def _closest(mesh, xs, backend="cpu", max_dist=1.0e6):
    return _query(mesh, xs, backend, max_dist, 0)


def _furthest(mesh, xs, backend="cpu", min_dist=0.0):
    return _query(mesh, xs, backend, min_dist, 1)


def _furthest_reference(pts, faces, xs):
    """Float64 distance from each query to the furthest vertex of a non-sliver face."""
    tri = pts.astype(np.float64)[faces]
    e0, e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], tri[:, 2] - tri[:, 1]
    with np.errstate(invalid="ignore"):
        keep = np.linalg.norm(np.cross(e0, e1), axis=1) / ((e0**2 + e1**2 + e2**2).sum(1)) >= 1e-6
    corners = tri[keep].reshape(-1, 3)
    return np.array([np.linalg.norm(corners - x, axis=1).max() for x in xs.astype(np.float64)])


def _queries(pts, n, seed=0):
    rng = np.random.default_rng(seed)
    lo, hi = pts.min(0), pts.max(0)
    c, h = (lo + hi) / 2, (hi - lo) / 2 * 1.3
    inside = c + h * rng.uniform(-1, 1, (n, 3))
    near = pts[rng.integers(0, len(pts), n // 4)] * rng.uniform(0.98, 1.02, (n // 4, 1))
    return np.vstack([inside, near, c[None]]).astype(np.float32)


def _adversarial():
    """A bumped icosphere with, appended: a copy of its first 30 faces (exact ties: the
    lower index must win), slivers (left out), a zero-area face and a far face."""
    pts, faces = icosphere(3, bumps=0.05, seed=3)
    extra_pts = np.array([[0.1, 0.1, 1.5], [0.2, 0.1, 1.5], [0.3, 0.1, 1.5 + 1e-9],  # sliver
                          [0.0, 0.0, -1.6], [0.0, 0.0, -1.6], [0.0, 0.0, -1.6],  # a point
                          [5.0, 5.0, 5.0], [5.1, 5.0, 5.0], [5.0, 5.1, 5.0]], np.float32)  # fmt: skip
    base = len(pts)
    extra = np.arange(base, base + 9, dtype=np.int32).reshape(3, 3)
    return np.vstack([pts, extra_pts]), np.vstack([faces, faces[:30], extra])


@pytest.mark.parametrize("backend", HOST_BACKENDS)
@pytest.mark.parametrize("constructor,leaf_size", [("lbvh", 4), ("sah", 1), ("median", 3)])
def test_wide_walk_answers_as_the_binary_walk_and_the_brute_force(
    backend, constructor, leaf_size, monkeypatch
):
    pts, faces = _adversarial()
    xs = _queries(pts, 48 if backend == "interp" else 400)
    xs = np.vstack([xs, [[np.nan, 0, 0]], pts[faces[5]].mean(0, keepdims=True)])  # NaN, on a face
    kw = {"bvh_constructor": constructor, "bvh_leaf_size": leaf_size}
    wide = _mesh(pts, faces, True, monkeypatch, **kw)
    binary = _mesh(pts, faces, False, monkeypatch, **kw)
    assert wide._wide is not None and binary._wide is None
    f_wide, d_wide = _closest(wide, xs, backend)
    f_bin, d_bin = _closest(binary, xs, backend)
    np.testing.assert_array_equal(f_wide, f_bin)
    np.testing.assert_array_equal(d_wide, d_bin)
    assert f_wide[-2] == -1  # the NaN point finds nothing
    assert not np.isin(f_wide, np.arange(len(faces) - 3, len(faces) - 1)).any()  # slivers
    finite = np.isfinite(xs).all(1)
    ref = closest_distances(pts, faces, xs[finite])
    np.testing.assert_allclose(d_wide[finite], ref, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("backend", HOST_BACKENDS)
@pytest.mark.parametrize("constructor,leaf_size", [("lbvh", 4), ("median", 2)])
def test_wide_furthest_point_answers_as_the_binary_walk_and_the_brute_force(
    backend, constructor, leaf_size, monkeypatch
):
    pts, faces = _adversarial()
    xs = _queries(pts, 40 if backend == "interp" else 300, seed=5)
    xs = np.vstack([xs, [[np.nan, 0, 0]]]).astype(np.float32)
    kw = {"bvh_constructor": constructor, "bvh_leaf_size": leaf_size}
    wide = _mesh(pts, faces, True, monkeypatch, **kw)
    binary = _mesh(pts, faces, False, monkeypatch, **kw)
    f_wide, d_wide = _furthest(wide, xs, backend)
    f_bin, d_bin = _furthest(binary, xs, backend)
    np.testing.assert_array_equal(f_wide, f_bin)
    np.testing.assert_array_equal(d_wide, d_bin)
    assert f_wide[-1] == -1  # the NaN point finds nothing
    np.testing.assert_allclose(d_wide[:-1], _furthest_reference(pts, faces, xs[:-1]), rtol=1e-5)
    # min_dist beyond every face: nothing; a negative one: every face counts
    assert (_furthest(wide, xs[:4], backend, min_dist=100.0)[0] == -1).all()
    np.testing.assert_array_equal(_furthest(wide, xs[:4], backend, min_dist=-1.0)[0], f_bin[:4])


def test_ties_go_to_the_lowest_face(monkeypatch):
    """The duplicated faces answer with the original (lower) index; points at the
    centre of a sphere, where every face is about as close, find the binary walk's."""
    pts, faces = _adversarial()
    mesh = _mesh(pts, faces, True, monkeypatch)
    xs = np.vstack([pts[faces[k]].mean(0) * 1.01 for k in range(30)]).astype(np.float32)
    face, _ = _closest(mesh, xs)
    np.testing.assert_array_equal(face, np.arange(30))
    center = np.zeros((1, 3), np.float32)
    assert _closest(mesh, center)[0][0] == _closest(_mesh(pts, faces, False, monkeypatch),
                                                    center)[0][0]  # fmt: skip


@pytest.mark.parametrize("backend", HOST_BACKENDS)
def test_max_dist_bounds_the_wide_walk(backend, monkeypatch):
    pts, faces = icosphere(2)
    mesh = _mesh(pts, faces, True, monkeypatch)
    xs = np.array([[0, 0, 1.5], [0, 0, 3.0], [0, 0, 0.0]], np.float32)
    face, dist = _closest(mesh, xs, backend, max_dist=0.9)  # (the centre is further)
    assert face[0] >= 0 and face[1] == -1 and face[2] == -1  # strictly below max_dist
    assert 0.49 < dist[0] < 0.51


def test_layout_covers_every_face_once_under_boxes_that_hold_it(monkeypatch):
    pts, faces = _adversarial()
    mesh = _mesh(pts, faces, True, monkeypatch)
    w = mesh._wide
    nodes, leaves = w.nodes.numpy(), w.leaves.numpy()
    lane_faces = leaves["face"]
    found = np.sort(lane_faces[lane_faces >= 0])
    tri = pts.astype(np.float64)[faces]
    e0, e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], tri[:, 2] - tri[:, 1]
    with np.errstate(invalid="ignore"):  # (the zero-area face: 0 / 0)
        ratio = np.linalg.norm(np.cross(e0, e1), axis=1) / ((e0**2 + e1**2 + e2**2).sum(1))
    np.testing.assert_array_equal(found, np.flatnonzero(ratio >= 1e-6))  # slivers left out
    seen = np.zeros(len(leaves), int)
    for nd in nodes:
        for i in range(4):
            c = nd["child"][i]
            if nd["src"][i] < 0:
                assert np.isnan(nd["lo_x"][i])
                continue
            lo = np.array([nd["lo_x"][i], nd["lo_y"][i], nd["lo_z"][i]])
            hi = np.array([nd["hi_x"][i], nd["hi_y"][i], nd["hi_z"][i]])
            if c < 0:
                seen[-c - 1] += 1
                lf = leaves[-c - 1]
                for j in range(4):
                    if lf["face"][j] >= 0:
                        corners = tri[lf["face"][j]]
                        assert (corners >= lo).all() and (corners <= hi).all()
            else:
                assert 0 < c < len(nodes)
    np.testing.assert_array_equal(seen, 1)  # every leaf under exactly one node


@pytest.mark.parametrize("backend", HOST_BACKENDS)
def test_wide_tree_follows_refit_assignment_and_rebuild(backend, monkeypatch):
    pts, faces = icosphere(3, bumps=0.02, seed=1)
    mesh = _mesh(pts, faces, True, monkeypatch)
    xs = _queries(pts, 40, seed=2)
    moved = (pts * np.float32(1.3) + np.float32(0.2)).astype(np.float32)
    mesh.points.assign(wp.array(moved, dtype=V3))  # in place, then refit
    mesh.refit()
    np.testing.assert_allclose(_closest(mesh, xs, backend)[1], closest_distances(moved, faces, xs),
                               rtol=1e-5, atol=1e-6)  # fmt: skip
    twisted = moved[:, [1, 2, 0]].copy()
    mesh.points = wp.array(twisted, dtype=V3)  # a new array: refits
    mesh.bvh.rebuild("sah")  # another tree: collapsed again
    np.testing.assert_allclose(_closest(mesh, xs, backend)[1],
                               closest_distances(twisted, faces, xs), rtol=1e-5, atol=1e-6)  # fmt: skip


def test_sign_of_mesh_query_point_through_the_wide_tree(monkeypatch):
    pts, faces = icosphere(2)
    xs = np.array([[0, 0, 0], [0.2, 0.1, -0.3], [0, 0, 2], [1.5, 0.1, 0]], np.float32)
    out = []
    for wide in (True, False):
        mesh = _mesh(pts, faces, wide, monkeypatch)
        sign = wp.zeros(len(xs), dtype=float)
        wp.launch(signed_kernel, dim=len(xs), inputs=[mesh.id, wp.array(xs, dtype=V3), sign])
        out.append(sign.numpy())
    np.testing.assert_array_equal(out[0], [-1, -1, 1, 1])
    np.testing.assert_array_equal(out[0], out[1])


def test_small_and_empty_meshes(monkeypatch):
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    one = _mesh(pts, np.array([[0, 1, 2]], np.int32), True, monkeypatch)
    assert one._wide.nodes.shape[0] == 1 and one._wide.leaves.shape[0] == 1
    assert _closest(one, np.array([[0.2, 0.2, 1.0]], np.float32))[0][0] == 0
    empty = _mesh(pts, np.zeros((0, 3), np.int32), True, monkeypatch)
    assert empty._wide.nodes.shape[0] == 0
    assert _closest(empty, np.array([[0.2, 0.2, 1.0]], np.float32))[0][0] == -1


def test_wide_leaves_only_for_leaves_of_four_faces(monkeypatch):
    """A BVH with leaves of up to 8 faces keeps no wide tree (its walk is the binary
    one); a collapse that meets such a leaf anyway refuses (``fallback``): the wide
    walk over it gives ``WIDE_OVERFLOW``, on which the queries walk the binary tree."""
    pts, faces = icosphere(2)
    mesh = _mesh(pts, faces, True, monkeypatch, bvh_leaf_size=8)
    assert mesh._wide is None and not wide_tree.wants_wide_tree(mesh.device, 8)
    xs = pts[:4] * 2
    np.testing.assert_allclose(_closest(mesh, xs)[1], closest_distances(pts, faces, xs),
                               rtol=1e-5)  # fmt: skip
    forced = wide_tree.WideTree(mesh._tree_points, mesh.device)
    forced.rebuild(mesh.bvh)
    assert forced.nodes.shape[0] == 0
    out = wp.zeros(len(xs), dtype=int)
    wp.launch(wide_id_kernel, dim=len(xs), inputs=[forced.id, wp.array(xs, dtype=V3), out])
    np.testing.assert_array_equal(out.numpy(), mesh_wide.WIDE_OVERFLOW)


def test_a_full_stack_falls_back_to_the_binary_walk(monkeypatch):
    """With a stack of 6 entries every walk over this tree runs out of room: the wide
    walk says so (``WIDE_OVERFLOW``) and the query's answer comes from the binary walk."""
    monkeypatch.setattr(mesh_wide, "WIDE_STACK", 6)

    @wp.kernel
    def short_stack(mesh: wp.uint64, xs: wp.array(dtype=V3), face: wp.array(dtype=int),
                    dist: wp.array(dtype=float)):  # fmt: skip
        i = wp.tid()
        face[i] = mesh_wide.wide_closest_face(wp.object_record(mesh, MeshRecord).wide, xs[i],
                                              1.0e6)  # fmt: skip
        q = wp.mesh_query_point_no_sign(mesh, xs[i], 1.0e6)
        dist[i] = wp.length(wp.mesh_eval_position(mesh, q.face, q.u, q.v) - xs[i])

    pts, faces = icosphere(3)
    mesh = _mesh(pts, faces, True, monkeypatch)
    xs = _queries(pts, 16)
    face, dist = wp.zeros(len(xs), dtype=int), wp.zeros(len(xs), dtype=float)
    wp.launch(short_stack, dim=len(xs), inputs=[mesh.id, wp.array(xs, dtype=V3), face, dist])
    assert (face.numpy() == mesh_wide.WIDE_OVERFLOW).all()
    np.testing.assert_allclose(dist.numpy(), closest_distances(pts, faces, xs), rtol=1e-5,
                               atol=1e-6)  # fmt: skip


def _host_has(feature: str) -> bool:
    import llvmlite.binding as llvm

    return bool(llvm.get_host_cpu_features().get(feature, False))


@pytest.mark.skipif(not _host_has("avx2"), reason="the vectorizer's choice depends on the host")
def test_the_leaf_test_vectorizes_across_lanes():
    # The leaf test's tree of operations is deeper than LLVM's default SLP limit (12):
    # cut there, the rest was vectorized across x/y/z within a lane (about 100
    # shufflevector and 220 two-float vectors in this kernel); with
    # kdsl.backends.cpu.jit.SLP_MAX_DEPTH it is one four-lane pass (17 and 16). The node
    # visit's four box distances are one four-lane pass too (the walk's prefetches come
    # before them: issued after, they split the distances into two-lane vectors, 100).
    from kdsl.backends.cpu import BACKEND
    from kdsl.compiler import lower

    text = lower(BACKEND, wide_id_kernel.build_module(), "llvm-ir", None)
    assert text.count("fdiv <4 x float>") == 4  # the leaf's four divisions, on lanes
    assert "fdiv float" not in text
    assert text.count("shufflevector") < 50
    assert text.count("<2 x float>") < 50
    assert "@llvm.prefetch" in text  # a node visit prefetches its children (kd.prefetch)


@pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")
def test_cuda_meshes_keep_no_wide_tree():
    pts, faces = icosphere(3)
    mesh = wp.Mesh(wp.array(pts, dtype=V3, device="cuda"),
                   wp.array(faces, dtype=wp.int32, device="cuda"))  # fmt: skip
    assert mesh._wide is None
    xs = _queries(pts, 64)
    dist = _query(mesh, xs, "cuda", 1.0e6, 0, device="cuda")[1]
    np.testing.assert_allclose(dist, closest_distances(pts, faces, xs), rtol=1e-5, atol=1e-6)
    far = _query(mesh, xs, "cuda", 0.0, 1, device="cuda")[1]
    np.testing.assert_allclose(far, _furthest_reference(pts, faces, xs), rtol=1e-5)
