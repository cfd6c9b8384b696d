"""The mesh queries' leaf-to-leaf walks (each query walks to the next leaf it must
test, then tests that leaf's faces) on trees deep enough to exercise them: a bumped
icosphere of 1,280 faces (5,120 off the interpreter) with leaves of 1 and 4 faces,
points inside (the centre, where every face is nearly as close as the closest),
outside and on the shell, against a float64 brute force; rays on a group's subtree
against the brute force over that group's faces; and a tree deeper than the ordered
walks' stack (``WALK_STACK``), where they take a stackless pass (for the closest ray
hit also one where a stack walk would lose the entry holding the first hit)."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.stdlib.bvh import BvhRecord
from kdsl.stdlib.mesh import WALK_STACK
from tests.geometry.mesh_reference import closest_distances, icosphere, ray_hits, winding_numbers

BACKENDS = [
    "interp",
    "cpu",
    pytest.param("cuda", marks=pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")),
]
V3 = wp.vec3


@wp.kernel
def points_kernel(
    mesh: wp.uint64, xs: wp.array(dtype=V3), near: wp.array(dtype=V3),
    signed: wp.array(dtype=float), far: wp.array(dtype=V3),
):  # fmt: skip
    i = wp.tid()
    q = wp.mesh_query_point_no_sign(mesh, xs[i], 1.0e6)
    near[i] = wp.mesh_eval_position(mesh, q.face, q.u, q.v)
    s = wp.mesh_query_point_sign_normal(mesh, xs[i], 1.0e6)
    signed[i] = s.sign
    f = wp.mesh_query_furthest_point_no_sign(mesh, xs[i], 0.0)
    far[i] = wp.mesh_eval_position(mesh, f.face, f.u, f.v)


@wp.kernel
def rays_kernel(
    mesh: wp.uint64, root: int, starts: wp.array(dtype=V3), dirs: wp.array(dtype=V3),
    t: wp.array(dtype=float), face: wp.array(dtype=int), anyhit: wp.array(dtype=int),
    count: wp.array(dtype=int),
):  # fmt: skip
    i = wp.tid()
    h = wp.mesh_query_ray(mesh, starts[i], dirs[i], 1.0e6, root)
    face[i] = -1
    if h.result:
        t[i] = h.t
        face[i] = h.face
    anyhit[i] = int(wp.mesh_query_ray_anyhit(mesh, starts[i], dirs[i], 1.0e6, root))
    count[i] = wp.mesh_query_ray_count_intersections(mesh, starts[i], dirs[i], root)


@wp.kernel
def group_root_kernel(mesh: wp.uint64, group: int, out: wp.array(dtype=int)):
    out[0] = wp.mesh_get_group_root(mesh, group)


def _device(backend: str) -> str:
    return "cuda" if backend == "cuda" else "cpu"


def _points(mesh, pts, faces, xs, backend, atol):
    """Runs ``points_kernel``, checks the closest points' distances against the brute
    force and returns the sign-normal signs and the furthest points (NumPy)."""
    dev = _device(backend)
    n = len(xs)
    near, signed, far = (wp.zeros(n, dtype=t, device=dev) for t in (V3, float, V3))
    wp.launch(points_kernel, dim=n, inputs=[mesh.id, wp.array(xs, dtype=V3, device=dev), near,
                                            signed, far], backend=backend, device=dev)  # fmt: skip
    np.testing.assert_allclose(
        np.linalg.norm(near.numpy() - xs, axis=1), closest_distances(pts, faces, xs),
        rtol=1e-5, atol=atol,
    )  # fmt: skip
    return signed.numpy(), far.numpy()


def _shell(backend: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The mesh and the query points: the centre, then points inside, near the shell
    and outside."""
    pts, faces = icosphere(3 if backend == "interp" else 4, bumps=0.05, seed=4)
    rng = np.random.default_rng(5)
    n = 6 if backend == "interp" else 40
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    radii = np.resize([0.3, 0.97, 1.02, 1.6], n)
    xs = np.vstack([np.zeros((1, 3)), d * radii[:, None]]).astype(np.float32)
    return pts, faces, xs


@pytest.mark.parametrize("leaf_size", [1, 4])
@pytest.mark.parametrize("backend", BACKENDS)
def test_point_walks_match_brute_force(backend, leaf_size):
    pts, faces, xs = _shell(backend)
    dev = _device(backend)
    mesh = wp.Mesh(wp.array(pts, dtype=V3, device=dev), wp.array(faces, dtype=wp.int32, device=dev),
                   bvh_leaf_size=leaf_size)  # fmt: skip
    signed, far = _points(mesh, pts, faces, xs, backend, atol=1e-6)
    inside = winding_numbers(pts, faces, xs) > 0.5
    np.testing.assert_array_equal(signed < 0, inside)
    furthest = np.linalg.norm(pts[None].astype(np.float64) - xs[:, None], axis=2).max(1)
    np.testing.assert_allclose(np.linalg.norm(far - xs, axis=1), furthest, rtol=1e-5)


@pytest.mark.parametrize("backend", BACKENDS)
def test_ray_walks_on_a_group_subtree_match_brute_force(backend):
    pts, faces, xs = _shell(backend)
    dev = _device(backend)
    groups = (np.arange(len(faces)) % 3 == 0).astype(np.int32)  # group 1: every third face
    mesh = wp.Mesh(wp.array(pts, dtype=V3, device=dev), wp.array(faces, dtype=wp.int32, device=dev),
                   groups=wp.array(groups, dtype=wp.int32, device=dev), bvh_leaf_size=2)  # fmt: skip
    rng = np.random.default_rng(6)
    dirs = rng.normal(size=xs.shape).astype(np.float32)
    n = len(xs)
    for group in (0, 1):
        root = wp.zeros(1, dtype=int, device=dev)
        wp.launch(group_root_kernel, dim=1, inputs=[mesh.id, group, root], backend=backend,
                  device=dev)  # fmt: skip
        t, face, anyhit, count = (wp.full(n, v, dtype=int if v == -1 else float, device=dev)
                                  for v in (np.inf, -1, -1, -1))  # fmt: skip
        inputs = [mesh.id, int(root.numpy()[0]), wp.array(xs, dtype=V3, device=dev),
                  wp.array(dirs, dtype=V3, device=dev), t, face, anyhit, count]  # fmt: skip
        wp.launch(rays_kernel, dim=n, inputs=inputs, backend=backend, device=dev)
        t, face, anyhit, count = (a.numpy() for a in (t, face, anyhit, count))
        mine = np.flatnonzero(groups == group)
        for i in range(n):
            ref = ray_hits(pts, faces[mine], xs[i], dirs[i])
            hit = np.isfinite(ref)
            assert count[i] == hit.sum() and anyhit[i] == hit.any(), (group, i)
            if hit.any():
                assert face[i] in mine, (group, i, face[i])
                np.testing.assert_allclose(t[i], ref.min(), rtol=1e-5)
            else:
                assert face[i] == -1


@wp.kernel
def depth_kernel(bvh: wp.uint64, out: wp.array(dtype=int)):
    """The depth of the BVH's deepest node (the root at 0), from its preorder links."""
    rec = wp.object_record(bvh, BvhRecord)
    ends = wp.zeros(128, dtype=wp.int32)  # the subtree ends of the node's ancestors
    top = 0
    deepest = 0
    n = rec.root
    stop = rec.skip[n]
    while n < stop:
        while top > 0 and ends[top - 1] <= n:
            top -= 1
        deepest = wp.max(deepest, top)
        nd = rec.nodes[n]
        if nd.first < 0:
            ends[top] = nd.next
            top += 1
        n += 1
    out[0] = deepest


def _deep_chain() -> tuple[np.ndarray, np.ndarray]:
    """Tiny triangles whose Morton codes are one bit each (a chain of 30 levels in an
    lbvh tree), then 40 in one Morton cell at the origin (split further by index),
    each tilted so that every one of their boxes holds the points just above the
    origin: the closest-point walk meets those boxes at distance 0 and goes left first,
    leaving the right siblings for the stack after it is full; the plane under those
    points lies lowest for the cluster's fourth face, one of them."""
    pts = []
    for j in range(30):
        c = np.zeros(3)
        c[j % 3] = 2.0 ** (j // 3) / 1024.0
        pts += [c, c + [1e-4, 0, 0], c + [0, 1e-4, 0]]
    for k in range(40):
        h = 1e-6 * (1 + (k - 3) % 40)  # the lowest: the cluster's fourth face
        pts += [[0.0, 0.0, 0.0], [4e-4, 0.0, h], [0.0, 4e-4, 2 * h]]
    pts += [[1.0, 1.0, 1.0], [1.0001, 1.0, 1.0], [1.0, 1.0001, 1.0]]
    pts = np.array(pts)
    return pts.astype(np.float32), np.arange(len(pts), dtype=np.int32).reshape(-1, 3)


@pytest.mark.parametrize("backend", BACKENDS)
def test_walks_deeper_than_the_stack_match_brute_force(backend):
    pts, faces = _deep_chain()
    dev = _device(backend)
    mesh = wp.Mesh(wp.array(pts, dtype=V3, device=dev), wp.array(faces, dtype=wp.int32, device=dev),
                   bvh_constructor="lbvh", bvh_leaf_size=1)  # fmt: skip
    depth = wp.zeros(1, dtype=int, device=dev)
    wp.launch(depth_kernel, dim=1, inputs=[mesh.bvh.id, depth], backend=backend, device=dev)
    assert depth.numpy()[0] > WALK_STACK + 1  # more nodes wait than the stack holds
    rng = np.random.default_rng(7)
    above = np.column_stack([rng.uniform(1e-5, 1e-4, (8, 2)), rng.uniform(0.0, 2e-7, 8)])
    xs = np.vstack([above, rng.uniform(-0.1, 1.1, (4, 3))])
    xs = xs.astype(np.float32)
    _points(mesh, pts, faces, xs, backend, atol=1e-9)
    n = len(xs)
    # rays down onto the cluster at the origin, from above
    starts = xs.copy()
    starts[:, 2] = 1.0
    dirs = np.tile(np.array([[0.0, 0.0, -1.0]], np.float32), (n, 1))
    t, face, anyhit, count = (wp.full(n, v, dtype=int if v == -1 else float, device=dev)
                              for v in (np.inf, -1, -1, -1))  # fmt: skip
    inputs = [mesh.id, -1, wp.array(starts, dtype=V3, device=dev),
              wp.array(dirs, dtype=V3, device=dev), t, face, anyhit, count]  # fmt: skip
    wp.launch(rays_kernel, dim=n, inputs=inputs, backend=backend, device=dev)
    t, face, count = t.numpy(), face.numpy(), count.numpy()
    for i in range(n):
        ref = ray_hits(pts, faces, starts[i], dirs[i])
        assert count[i] == np.isfinite(ref).sum()
        if np.isfinite(ref).any():
            np.testing.assert_allclose(t[i], ref.min(), rtol=1e-6)
        else:
            assert face[i] == -1


def _wide_chain(winner: int) -> tuple[np.ndarray, np.ndarray]:
    """``_deep_chain``'s tree (the faces' box centres kept) with every face grown to a
    cube 8 wide about its centre, so that a ray along ``(1, 1, 0)`` near the origin
    enters every node's box and the closest-hit walk pushes a node at every level
    (more than ``WALK_STACK``: the deepest pushes are lost). The chain's faces lie in
    planes ``x - y + z = c`` (parallel to those rays: missed); the 40 faces of the
    cluster contain their cube's diagonal and turn about it, and face ``winner``'s
    turn makes it the first hit: one of the cluster's right subtrees near the bottom,
    which the walk can only reach in its stackless pass after the overflow."""
    pts, faces = _deep_chain()
    tri = pts[faces].astype(np.float64)
    centres = 0.5 * (tri.min(axis=1) + tri.max(axis=1))
    m = len(centres)
    shapes = np.empty((m, 3, 3))
    shapes[:] = [[-1, -1, -1], [1, 1, -1], [-1, 1, 1]]  # plane x - y + z = -1 (relative)
    turn = np.random.default_rng(0).uniform(-1.0, 0.5, m)
    turn[winner] = 0.9  # (the plane (1 + s) x + (1 - s) y - 2 z = 0: s = 0.9 is hit first)
    cluster = np.arange(30, 70)
    shapes[cluster, 0] = [-1, -1, -1]
    shapes[cluster, 1] = [1, 1, 1]
    shapes[cluster, 2] = np.column_stack([np.ones(40), -np.ones(40), turn[cluster]])
    out = (centres[:, None, :] + 4.0 * shapes).astype(np.float32)
    return out.reshape(-1, 3), np.arange(3 * m, dtype=np.int32).reshape(-1, 3)


@pytest.mark.parametrize("backend", BACKENDS)
def test_ray_walks_overflowing_the_stack_match_brute_force(backend):
    """A tree taller than the closest hit's stack, on which a stack walk would overflow
    on every ray and lose the entry holding the first hit (a stack walk answers another
    face here): the walk must take its stackless pass (``BvhRecord.height``); any hit
    and counted hits are checked too."""
    dev = _device(backend)
    rng = np.random.default_rng(3)
    n = 8 if backend == "interp" else 16
    y0 = -20.0 + rng.uniform(-2.0, 2.0, n)
    starts = np.column_stack([y0 + 1.5, y0, rng.uniform(-2.0, 2.0, n)]).astype(np.float32)
    dirs = np.tile(np.array([[1.0, 1.0, 0.0]], np.float32), (n, 1))
    for winner in (33, 34):
        pts, faces = _wide_chain(winner)
        mesh = wp.Mesh(wp.array(pts, dtype=V3, device=dev),
                       wp.array(faces, dtype=wp.int32, device=dev), bvh_constructor="lbvh",
                       bvh_leaf_size=1)  # fmt: skip
        depth = wp.zeros(1, dtype=int, device=dev)
        wp.launch(depth_kernel, dim=1, inputs=[mesh.bvh.id, depth], backend=backend, device=dev)
        assert depth.numpy()[0] > WALK_STACK + 1
        t, face, anyhit, count = (wp.full(n, v, dtype=int if v == -1 else float, device=dev)
                                  for v in (np.inf, -1, -1, -1))  # fmt: skip
        inputs = [mesh.id, -1, wp.array(starts, dtype=V3, device=dev),
                  wp.array(dirs, dtype=V3, device=dev), t, face, anyhit, count]  # fmt: skip
        wp.launch(rays_kernel, dim=n, inputs=inputs, backend=backend, device=dev)
        t, face, anyhit, count = (a.numpy() for a in (t, face, anyhit, count))
        for i in range(n):
            ref = ray_hits(pts, faces, starts[i], dirs[i])
            assert count[i] == np.isfinite(ref).sum() and anyhit[i] == 1
            assert face[i] == winner == np.argmin(ref), (winner, i, face[i])
            np.testing.assert_allclose(t[i], ref.min(), rtol=1e-6)
