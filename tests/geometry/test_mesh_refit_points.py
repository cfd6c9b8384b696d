"""A mesh's ``refit()``: the check (faces' boxes, edge lengths, the index and finite
checks), then the BVH's refit (``device_tree``: bottom up through parity arrival
counters, a GPU's way, or the leaves then one thread in reverse preorder, a CPU's; whole
packed nodes) and the gather of the vertex copy (``MeshRecord.tri``), both issued before
the host has the check's answers and writing nothing when they are set. Checked after
every vertex moved against a float64 brute force (each node's box is the union of its
faces' corners, the copy holds the corners in item order, the queries find the brute
force's answers), with groups, several leaf sizes and constructors, degenerate and
empty meshes; a refit that finds a bad point or index keeps the bounds and the copy.
The bottom-up kernel runs on the CPU's threads here too; interp runs the check, the
gather and both refit kernels; cuda on the GPU machine."""

from __future__ import annotations

import functools

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslTypeError
from kdsl.geometry import bvh as bvh_module
from kdsl.geometry import lbvh
from kdsl.geometry.device_tree import _refit_inner_reverse_preorder, _refit_leaves
from kdsl.geometry.mesh_refit import _checked_face_boxes
from kdsl.geometry.mesh_tree_points import _gather_tree_points
from kdsl.utils.chunk_sum import sum_levels
from tests.geometry.mesh_reference import icosphere
from tests.geometry.test_mesh_tree_points import _check_copy, _check_queries, move_kernel

cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")
DEVICES = ["cpu", pytest.param("cuda:0", marks=cuda)]
V3 = wp.vec3


@pytest.fixture
def bottom_up_on_cpu(monkeypatch):
    """lbvh trees with parent links (the GPU's bottom-up refit) on the CPU too."""
    monkeypatch.setitem(bvh_module.CONSTRUCTORS, "lbvh",
                        functools.partial(lbvh.build_lbvh, bottom_up=True))  # fmt: skip


def _brute_force_bounds(mesh, pts: np.ndarray, faces: np.ndarray):
    """Each node's box from the faces' corners (float64 min/max of float32 values: the
    exact float32 bounds), children before parents; and the corners in item order."""
    tree = mesh.bvh._tree
    m = tree.num_nodes
    first, count = tree.first.numpy()[:m], tree.count.numpy()[:m]
    skip, items = tree.skip.numpy()[:m], tree.items.numpy()
    corners = pts.astype(np.float64)[faces]
    lo, hi = np.empty((m, 3)), np.empty((m, 3))
    for n in range(m - 1, -1, -1):
        if first[n] >= 0:
            c = corners[items[first[n] : first[n] + count[n]]].reshape(-1, 3)
            lo[n], hi[n] = c.min(axis=0), c.max(axis=0)
        else:
            a = n + 1
            b = skip[a]
            lo[n], hi[n] = np.minimum(lo[a], lo[b]), np.maximum(hi[a], hi[b])
    return lo, hi, pts[faces[items]].reshape(-1, 3)


def _node_bounds(mesh):
    nodes = mesh.bvh._nodes.numpy()[: mesh.bvh._tree.num_nodes]
    return nodes["lower"], nodes["upper"]


def _check_against_brute_force(mesh, faces: np.ndarray) -> None:
    pts = mesh.points.numpy()
    want_lo, want_hi, want_tri = _brute_force_bounds(mesh, pts, faces)
    got_lo, got_hi = _node_bounds(mesh)
    np.testing.assert_array_equal(got_lo, want_lo.astype(np.float32))
    np.testing.assert_array_equal(got_hi, want_hi.astype(np.float32))
    np.testing.assert_array_equal(mesh._tree_points.tri.numpy(), want_tri)
    # every face inside each leaf holding it (the brute force's containment)
    tree = mesh.bvh._tree
    first, count = tree.first.numpy(), tree.count.numpy()
    items = tree.items.numpy()
    for n in np.flatnonzero(first[: tree.num_nodes] >= 0):
        c = pts[faces[items[first[n] : first[n] + count[n]]]].reshape(-1, 3)
        assert np.all(c >= got_lo[n]) and np.all(c <= got_hi[n])


def _moves(mesh, pts, faces, steps=3):
    """Move every vertex (in place, then by assignment), refit, yield after each."""
    dev = mesh.device
    rng = np.random.default_rng(5)
    for step in range(steps):
        if step % 2 == 0:
            shift = wp.vec3(*rng.uniform(-1, 1, 3).astype(np.float32))
            wp.launch(move_kernel, dim=len(pts), inputs=[mesh.points, shift, 1.0 + 0.3 * step],
                      device=dev)  # fmt: skip
            mesh.refit()
        else:
            wobble = 1.0 + 0.2 * rng.uniform(-1, 1, (len(pts), 1))
            mesh.points = wp.array((mesh.points.numpy() * wobble).astype(np.float32), dtype=V3,
                                   device=dev)  # fmt: skip
        yield step


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("bottom_up", [False, True])
@pytest.mark.parametrize("leaf_size", [1, 4])
@pytest.mark.parametrize("num_groups", [0, 3])
def test_refit_after_moves_matches_brute_force(device, bottom_up, leaf_size, num_groups, request):
    if bottom_up and device == "cpu":
        request.getfixturevalue("bottom_up_on_cpu")
    pts, faces = icosphere(2, bumps=0.05, seed=3)
    groups = None
    if num_groups:
        g = np.random.default_rng(1).integers(0, num_groups, len(faces)).astype(np.int32)
        groups = wp.array(g, dtype=wp.int32, device=device)
    mesh = wp.Mesh(wp.array(pts, dtype=V3, device=device),
                   wp.array(faces, dtype=wp.int32, device=device), groups=groups,
                   bvh_leaf_size=leaf_size)  # fmt: skip
    assert bool(mesh.bvh._tree.parent.shape[0]) == (bottom_up or device != "cpu")
    for _ in _moves(mesh, pts, faces):
        _check_against_brute_force(mesh, faces)
        moved = mesh.points.numpy()[faces]  # the faces' boxes, as the check writes them
        np.testing.assert_array_equal(mesh._faces.lowers.numpy(), moved.min(axis=1))
        np.testing.assert_array_equal(mesh._faces.uppers.numpy(), moved.max(axis=1))
    arrivals = mesh.bvh._tree.arrivals.numpy()
    assert not (arrivals & 1).any()  # ready for the next refit
    backend = "cuda" if device != "cpu" else "cpu"
    _check_copy(mesh, backend)
    _check_queries(mesh, mesh.points.numpy(), faces, backend)


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("constructor", ["sah", "median"])
def test_refit_of_host_built_trees(device, constructor):
    pts, faces = icosphere(2, bumps=0.05, seed=4)
    mesh = wp.Mesh(
        wp.array(pts, dtype=V3, device=device),
        wp.array(faces, dtype=wp.int32, device=device),
        bvh_constructor=constructor,
    )
    for _ in _moves(mesh, pts, faces, steps=2):
        _check_against_brute_force(mesh, faces)
    mesh.bvh.rebuild("lbvh")  # another tree: the refit's launches are prepared again
    for _ in _moves(mesh, pts, faces, steps=2):
        _check_against_brute_force(mesh, faces)


@pytest.mark.parametrize("device", DEVICES)
def test_degenerate_faces_and_a_single_face(device, bottom_up_on_cpu):
    # every face a point or a segment (repeated corners), then one face alone
    pts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 1]], np.float32)
    faces = np.array([[0, 0, 0], [1, 1, 2], [2, 3, 2], [3, 3, 3], [0, 1, 0]], np.int32)
    for f in (faces, faces[1:2]):
        mesh = wp.Mesh(wp.array(pts, dtype=V3, device=device),
                       wp.array(f, dtype=wp.int32, device=device))  # fmt: skip
        for _ in _moves(mesh, pts, f):
            _check_against_brute_force(mesh, f)


@pytest.mark.parametrize("device", DEVICES)
def test_meshes_without_faces_refit(device, bottom_up_on_cpu):
    for n in (0, 5):  # no points and no faces; points but no faces
        mesh = wp.Mesh(wp.zeros(n, dtype=V3, device=device),
                       wp.zeros(0, dtype=wp.int32, device=device))  # fmt: skip
        mesh.refit()
        mesh.points = wp.ones(n, dtype=V3, device=device)
        assert mesh.bvh._tree.slots == 0


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("bottom_up", [False, True])
def test_a_bad_point_or_index_keeps_the_bounds_and_the_copy(device, bottom_up, request):
    if bottom_up and device == "cpu":
        request.getfixturevalue("bottom_up_on_cpu")
    pts, faces = icosphere(1, bumps=0.05, seed=2)
    points = wp.array(pts, dtype=V3, device=device)
    indices = wp.array(faces, dtype=wp.int32, device=device)
    mesh = wp.Mesh(points, indices)
    before = (mesh.bvh._nodes.numpy().tobytes(), mesh._tree_points.tri.numpy().tobytes())
    bad = pts * 2.0
    bad[4, 2] = np.inf
    wp.copy(points, wp.array(bad, dtype=V3, device=device))
    with pytest.raises(KdslTypeError, match="point 4 is not finite"):
        mesh.refit()
    assert (mesh.bvh._nodes.numpy().tobytes(), mesh._tree_points.tri.numpy().tobytes()) == before
    wrong = faces.copy()
    wrong[3, 1] = len(pts) + 7  # an index changed in place after construction
    wp.copy(mesh.indices, wp.array(wrong.ravel(), dtype=wp.int32, device=device))
    with pytest.raises(KdslTypeError, match=f"out of range: {len(pts) + 7}"):
        mesh.refit()  # (nothing out of range is read)
    assert (mesh.bvh._nodes.numpy().tobytes(), mesh._tree_points.tri.numpy().tobytes()) == before
    wp.copy(mesh.indices, wp.array(faces.ravel(), dtype=wp.int32, device=device))
    wp.copy(points, wp.array(pts * 2.0, dtype=V3, device=device))
    mesh.refit()  # the counters were left ready: a good refit after bad ones
    _check_against_brute_force(mesh, faces)


@pytest.mark.parametrize("bottom_up", [False, True])
def test_refit_kernels_on_interp_match_cpu(bottom_up, bottom_up_on_cpu):
    """The refit's kernels run by the interpreter (the mesh's arrays on the CPU): the
    same face boxes, copy and node bounds as the cpu backend's."""
    pts, faces = icosphere(1, bumps=0.1, seed=6)
    mesh = wp.Mesh(wp.array(pts * 1.5, dtype=V3), wp.array(faces, dtype=wp.int32),
                   bvh_leaf_size=2)  # fmt: skip
    mesh.refit()
    boxes, copy, tree = mesh._faces, mesh._tree_points, mesh.bvh._tree
    nodes = mesh.bvh._nodes
    want = (nodes.numpy().copy(), copy.tri.numpy().copy(), boxes.lowers.numpy().copy())
    scratch = nodes.numpy()
    scratch["lower"], scratch["upper"] = 7.0, -7.0
    wp.copy(nodes, wp.array(scratch, dtype=nodes.dtype))
    copy.tri.zero_()
    boxes.lowers.zero_()
    n_pts, n_tris = len(pts), len(faces)
    wp.launch(
        _checked_face_boxes,
        dim=max(n_pts, n_tris),
        backend="interp",
        inputs=[copy.points, copy.indices, n_pts, n_tris, boxes.lowers, boxes.uppers,
                boxes.edges, boxes.found],
    )  # fmt: skip
    wp.launch(_gather_tree_points, dim=3 * n_tris, backend="interp",
              inputs=[copy.points, copy.indices, copy.items, boxes.found, copy.tri])  # fmt: skip
    none = wp.empty(0, dtype=wp.int32)  # no parent links: the leaves only
    links = [tree.skip, tree.parent, tree.arrivals] if bottom_up else [tree.skip, none, none]
    wp.launch(_refit_leaves, dim=tree.slots, backend="interp",
              inputs=[tree.first, tree.count, tree.items, boxes.lowers, boxes.uppers, *links,
                      boxes.found, nodes])  # fmt: skip
    if not bottom_up:
        wp.launch(_refit_inner_reverse_preorder, dim=1, backend="interp",
                  inputs=[tree.slots, tree.first, tree.skip, boxes.found, nodes])  # fmt: skip
    m = tree.num_nodes
    np.testing.assert_array_equal(nodes.numpy()[:m], want[0][:m])
    np.testing.assert_array_equal(copy.tri.numpy(), want[1])
    np.testing.assert_array_equal(boxes.lowers.numpy(), want[2])


@pytest.mark.parametrize("device", DEVICES)
def test_the_refit_runs_its_three_launches_side_by_side(device, monkeypatch):
    """Without a wide tree (a GPU's meshes; here on the CPU too) a refit issues the BVH's
    refit, the edge sum and the copy's gather behind the check as one ``ForkedSteps``
    (on a GPU: the BVH refit on the stream, the other two on side streams, joined back):
    the same one refit after refit (a CUDA graph from the second), a new one when the
    points array or the tree changes; answers as the brute force's (queries included,
    which run behind the join), and a bad point still raises and keeps the bounds and
    the copy, in the graph too."""
    from kdsl.geometry import wide_tree

    monkeypatch.setitem(wide_tree.WIDE_TREE, "cpu", False)
    pts, faces = icosphere(2, bumps=0.05, seed=8)
    points = wp.array(pts, dtype=V3, device=device)
    mesh = wp.Mesh(points, wp.array(faces, dtype=wp.int32, device=device))
    assert mesh._wide is None
    tails = []
    for _ in _moves(mesh, pts, faces, steps=4):
        _check_against_brute_force(mesh, faces)
        tails.append(mesh._faces._tails[-1][3])
    fork = tails[-1]
    gather = mesh._tree_points.prepared(mesh._faces.beside_stream())
    refit = mesh.bvh.refit_checked_steps(mesh._faces.found)
    levels = len(sum_levels(len(faces)))
    assert all(any(s is f for f in fork.steps) for s in refit) and fork.steps[-1] is gather
    if device == "cpu":  # the check and the read back issued before it, then one by one
        assert len(fork.steps) == len(refit) + levels + 1 and not fork.head
    else:  # the check, then the BVH refit beside the read back + the sum, and the gather
        assert fork.head == [mesh._faces._check[3]] and fork.main == refit
        assert [len(b[1]) for b in fork.branches] == [1 + levels, 1]
    # moves 1 and 3 assign new points (a new gather, a new fork), 2 moves them in place
    assert tails[1] is tails[2] and len({id(t) for t in tails}) == 3
    if device != "cpu":
        assert tails[2].graph is not None  # its second run captured it
    _check_queries(mesh, mesh.points.numpy(), faces, "cuda" if device != "cpu" else "cpu")
    mesh.bvh.rebuild("median")  # another tree: other refit launches, another fork
    for _ in _moves(mesh, pts, faces, steps=2):
        _check_against_brute_force(mesh, faces)
    assert mesh._faces._tails[-1][3] is not tails[-1]
    before = (mesh.bvh._nodes.numpy().tobytes(), mesh._tree_points.tri.numpy().tobytes())
    edge_sum = mesh._faces.edge_sum.numpy()[0]
    bad = mesh.points.numpy() * 1.5
    bad[9, 0] = np.nan
    wp.copy(mesh.points, wp.array(bad, dtype=V3, device=device))
    for _ in range(2):  # (the second time through the replayed graph)
        with pytest.raises(KdslTypeError, match="point 9 is not finite"):
            mesh.refit()
        assert (mesh.bvh._nodes.numpy().tobytes(),
                mesh._tree_points.tri.numpy().tobytes()) == before  # fmt: skip
        assert mesh._faces.edge_sum.numpy()[0] == edge_sum
    bad[9, 0] = 0.5
    wp.copy(mesh.points, wp.array(bad, dtype=V3, device=device))
    mesh.refit()
    _check_against_brute_force(mesh, faces)


@pytest.mark.parametrize("device", DEVICES)
def test_a_refit_inside_a_capture_is_refused(device):
    """A refit waits for its check's answers, which a graph capture cannot hold: inside
    one it raises before issuing anything, and the mesh refits as before after it."""
    from kdsl.errors import KdslError

    pts, faces = icosphere(1, bumps=0.05, seed=3)
    mesh = wp.Mesh(wp.array(pts, dtype=V3, device=device),
                   wp.array(faces, dtype=wp.int32, device=device))  # fmt: skip
    mesh.refit()
    with wp.ScopedCapture(device=device), pytest.raises(KdslError, match="capture"):
        mesh.refit()
    wp.copy(mesh.points, wp.array(pts * 1.5, dtype=V3, device=device))
    mesh.refit()
    _check_against_brute_force(mesh, faces)
