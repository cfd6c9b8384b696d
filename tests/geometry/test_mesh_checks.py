"""The mesh's one checking kernel (``kdsl.geometry.mesh_refit.FaceBoxes.write``): the
index and finiteness checks and the face boxes of a construction or a refit, in one launch
and one read back, into arrays allocated once per mesh; on cpu and (on the GPU machine)
cuda."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslTypeError
from kdsl.geometry.mesh_refit import FaceBoxes

cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")
DEVICES = ["cpu", pytest.param("cuda:0", marks=cuda)]

PTS = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [2, 2, 2], [3, 3, 3]], np.float32)
FACES = np.array([[0, 1, 2], [1, 3, 2], [4, 5, 5]], np.int32)


def _check(pts, faces, device, boxes=None):
    p = wp.array(pts, dtype=wp.vec3, device=device)
    idx = wp.array(faces.ravel(), dtype=wp.int32, device=device)
    if boxes is None:
        boxes = FaceBoxes(faces.shape[0], device)
        boxes.edge_sum.fill_(-1.0)
    bad = boxes.write(p, idx)
    return bad, boxes.lowers.numpy(), boxes.uppers.numpy(), boxes.edge_sum.numpy()[0]


@pytest.mark.parametrize("device", DEVICES)
def test_good_meshes_get_their_boxes_and_edge_sum(device):
    bad, lo, hi, total = _check(PTS, FACES, device)
    assert bad == (-1, -1)
    tri = PTS[FACES]
    np.testing.assert_array_equal(lo, tri.min(axis=1))
    np.testing.assert_array_equal(hi, tri.max(axis=1))
    e = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).sum()
    np.testing.assert_allclose(total, e, rtol=1e-6)
    # More faces than points and more points than faces: every item is seen once.
    many = np.tile(FACES, (7, 1))
    assert _check(PTS, many, device)[0] == (-1, -1)
    assert _check(np.tile(PTS, (9, 1)), FACES[:1], device)[0] == (-1, -1)


@pytest.mark.parametrize("device", DEVICES)
def test_the_first_bad_index_and_the_first_bad_point_come_back(device):
    faces = np.array([[0, 1, 2], [1, 9, -3], [7, 0, 1], [0, 1, 2]], np.int32)
    pts = PTS.copy()
    pts[4, 1] = np.inf
    pts[2, 0] = np.nan
    bad, lo, _, total = _check(pts, faces, device)
    assert bad == (4, 2)  # position 4 (the 9) comes before 5 and 6; point 2 before 4
    assert total == -1.0  # the edge sum is left as it was
    np.testing.assert_array_equal(lo[1], [0, 0, 0])  # a bad face reads no point: zeros
    assert _check(PTS, faces, device)[0] == (4, -1)
    assert _check(pts, FACES, device)[0] == (-1, 2)


@pytest.mark.parametrize("device", DEVICES)
def test_one_face_boxes_serves_call_after_call(device):
    """The counters hold "nothing found" between calls: a call that finds a bad value
    resets them, so the next good call on the same arrays reports nothing."""
    faces = FACES.copy()
    boxes = FaceBoxes(len(faces), device)
    boxes.edge_sum.fill_(-1.0)
    bad_pts = PTS.copy()
    bad_pts[3, 2] = -np.inf
    tri = PTS[FACES]
    want = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).sum()
    for pts, expect in [(PTS, (-1, -1)), (bad_pts, (-1, 3)), (PTS, (-1, -1)), (PTS * 2, (-1, -1)),
                        (bad_pts, (-1, 3)), (bad_pts, (-1, 3)), (PTS, (-1, -1))]:  # fmt: skip
        bad, lo, _, total = _check(pts, faces, device, boxes)
        assert bad == expect
        if bad == (-1, -1):
            np.testing.assert_array_equal(lo, pts[FACES].min(axis=1))
            np.testing.assert_allclose(total, want * (2 if pts is not PTS else 1), rtol=1e-6)
    faces[1, 1] = 6
    assert _check(PTS, faces, device, boxes)[0] == (4, -1)
    assert _check(PTS, FACES, device, boxes)[0] == (-1, -1)


@pytest.mark.parametrize("device", DEVICES)
def test_no_faces_sum_to_zero(device):
    boxes = FaceBoxes(0, device)
    assert _check(PTS, np.zeros((0, 3), np.int32), device, boxes)[0] == (-1, -1)
    assert boxes.edge_sum.numpy().tolist() == [0.0] and boxes.none.shape == (0,)
    bad_pts = PTS.copy()
    bad_pts[1, 0] = np.nan
    assert _check(bad_pts, np.zeros((0, 3), np.int32), device, boxes)[0] == (-1, 1)


@pytest.mark.parametrize("device", DEVICES)
def test_mesh_reports_indices_before_points_and_refit_recovers(device):
    pts = PTS.copy()
    pts[5] = np.nan
    with pytest.raises(KdslTypeError, match="out of range: 6"):
        wp.Mesh(wp.array(pts, dtype=wp.vec3, device=device),
                wp.array(np.array([[0, 1, 6]], np.int32), device=device))  # fmt: skip
    mesh = wp.Mesh(wp.array(PTS, dtype=wp.vec3, device=device),
                   wp.array(FACES, dtype=wp.int32, device=device))  # fmt: skip
    root = mesh.bvh._nodes.numpy()[0].copy()
    moved = wp.array(pts, dtype=wp.vec3, device=device)
    with pytest.raises(KdslTypeError, match="point 5 is not finite"):
        mesh.points = moved
    assert mesh.bvh._nodes.numpy()[0] == root  # the BVH did not take the bad points
    moved = wp.array(PTS * 2, dtype=wp.vec3, device=device)
    mesh.points = moved
    np.testing.assert_array_equal(mesh.bvh._nodes.numpy()[0]["upper"], [6, 6, 6])
