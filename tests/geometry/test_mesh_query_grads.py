"""Gradients through every point query (``kdsl.Tape``), struct and out-argument forms,
on interp, cpu and cuda: the closest (or furthest) point on the face found, with respect
to the query point, matches central finite differences. As in Warp 1.19, the face's
search carries no gradient and the mesh's points get none (Warp's adjoints drop them)."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from tests.geometry.mesh_reference import icosphere
from tests.geometry.mesh_targets import BACKENDS, central_differences, device_of

V3 = wp.vec3
#: Query kinds: the six struct forms (no_sign, point, sign_normal, sign_parity,
#: sign_winding_number, furthest_point_no_sign), then the seeds' out-argument forms of
#: mesh_query_point and mesh_query_point_no_sign.
KINDS = range(8)


def _point_loss(kind: int):
    """A kernel for query ``kind`` alone (one query per kernel keeps compiles short)."""

    @wp.kernel
    def point_loss(mesh: wp.uint64, xs: wp.array(dtype=V3), out: wp.array(dtype=V3)):
        i = wp.tid()
        x = xs[i]
        q = wp.MeshQueryPoint()
        if wp.static(kind == 0):
            q = wp.mesh_query_point_no_sign(mesh, x, 1.0e6)
        elif wp.static(kind == 1):
            q = wp.mesh_query_point(mesh, x, 1.0e6)
        elif wp.static(kind == 2):
            q = wp.mesh_query_point_sign_normal(mesh, x, 1.0e6)
        elif wp.static(kind == 3):
            q = wp.mesh_query_point_sign_parity(mesh, x, 1.0e6)
        elif wp.static(kind == 4):
            q = wp.mesh_query_point_sign_winding_number(mesh, x, 1.0e6)
        elif wp.static(kind == 5):
            q = wp.mesh_query_furthest_point_no_sign(mesh, x, 0.0)
        else:
            sign = 0.0
            face = 0
            u = 0.0
            v = 0.0
            if wp.static(kind == 6):
                q.result = wp.mesh_query_point(mesh, x, 1.0e6, sign, face, u, v)
            else:
                q.result = wp.mesh_query_point_no_sign(mesh, x, 1.0e6, face, u, v)
            q.face = face
            q.u = u
            q.v = v
        if q.result:
            out[i] = wp.mesh_eval_position(mesh, q.face, q.u, q.v)

    return point_loss


LOSSES = [_point_loss(kind) for kind in KINDS]


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("kind", KINDS)
def test_point_query_gradient_matches_finite_differences(backend, kind):
    dev = device_of(backend)
    pts, faces = icosphere(1, bumps=0.1, seed=7)
    points = wp.array(pts, dtype=V3, device=dev, requires_grad=True)
    mesh = wp.Mesh(points, wp.array(faces, dtype=wp.int32, device=dev), support_winding_number=True)
    # inside, outside, beyond an edge or a vertex: away from ties between faces
    xs0 = np.array([[0.13, 0.27, 0.41], [1.6, 0.35, -0.22], [-0.31, -1.3, 0.52],
                    [0.05, 0.1, -0.2]], np.float32)  # fmt: skip
    n = len(xs0)
    w = np.array([[1.0, -2.0, 0.5]] * n, np.float32)

    def loss(x: np.ndarray) -> np.ndarray:
        out = wp.zeros(n, dtype=V3, device=dev)
        wp.launch(LOSSES[kind], dim=n, backend=backend, device=dev,
                  inputs=[mesh.id, wp.array(x, dtype=V3, device=dev), out])  # fmt: skip
        return (out.numpy().astype(np.float64) * w).sum(axis=1)

    xs = wp.array(xs0, dtype=V3, device=dev, requires_grad=True)
    out = wp.zeros(n, dtype=V3, device=dev, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(LOSSES[kind], dim=n, inputs=[mesh.id, xs, out], backend=backend, device=dev)
    tape.backward(grads={out: wp.array(w, dtype=V3, device=dev)})
    fd = central_differences(loss, xs0)
    np.testing.assert_allclose(xs.grad.numpy(), fd, atol=2e-2)
    if kind == 5:  # the furthest point is a vertex: it does not move with the query
        np.testing.assert_array_equal(fd, 0)
    else:
        assert np.abs(fd).max() > 0.5  # the check is not trivially zero
    assert not np.any(points.grad.numpy())  # no gradient for mesh points (as Warp)
