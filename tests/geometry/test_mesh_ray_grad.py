"""Gradients through ``mesh_query_ray`` (``kdsl.Tape``): the hit's ``t`` and
barycentrics with respect to the ray's start and direction match central finite
differences. The search for the face reads a thread-local stack; the backward pass
replays it whole (``func_grad``), and the gradient flows through the hit on that face."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from tests.geometry.mesh_reference import icosphere

BACKENDS = [
    "interp",
    "cpu",
    pytest.param("cuda", marks=pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")),
]
V3 = wp.vec3
#: Weights of ``t``, ``u``, ``v`` in the loss.
W = (1.0, 0.5, -2.0)


@wp.kernel
def ray_loss(mesh: wp.uint64, start: wp.array(dtype=V3), d: wp.array(dtype=V3),
             out: wp.array(dtype=float)):  # fmt: skip
    i = wp.tid()
    q = wp.mesh_query_ray(mesh, start[i], d[i], 100.0)
    out[i] = W[0] * q.t + W[1] * q.u + W[2] * q.v


@pytest.mark.parametrize("backend", BACKENDS)
def test_ray_hit_gradient_matches_finite_differences(backend):
    dev = "cuda" if backend == "cuda" else "cpu"
    pts, faces = icosphere(1, bumps=0.1, seed=5)
    mesh = wp.Mesh(wp.array(pts, dtype=V3, device=dev), wp.array(faces, dtype=wp.int32, device=dev))
    s0 = np.array([[0.11, 0.23, -3.0], [2.5, 0.31, 0.17]], np.float32)
    d0 = np.array([[0.05, -0.02, 1.0], [-1.0, 0.03, 0.08]], np.float32)
    n = len(s0)

    def loss(s, d):
        out = wp.zeros(n, dtype=float, device=dev)
        wp.launch(ray_loss, dim=n, backend=backend, device=dev,
                  inputs=[mesh.id, wp.array(s, dtype=V3, device=dev),
                          wp.array(d, dtype=V3, device=dev), out])  # fmt: skip
        return out.numpy().astype(np.float64)

    s = wp.array(s0, dtype=V3, device=dev, requires_grad=True)
    d = wp.array(d0, dtype=V3, device=dev, requires_grad=True)
    out = wp.zeros(n, dtype=float, device=dev, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(ray_loss, dim=n, inputs=[mesh.id, s, d, out], backend=backend, device=dev)
    tape.backward(grads={out: wp.ones(n, dtype=float, device=dev)})
    h = 1e-3
    for arr, x0, others in ((s, s0, lambda x: (x, d0)), (d, d0, lambda x: (s0, x))):
        fd = np.zeros((n, 3))
        for k in range(3):
            dx = np.zeros_like(x0)
            dx[:, k] = h
            fd[:, k] = (loss(*others(x0 + dx)) - loss(*others(x0 - dx))) / (2 * h)
        np.testing.assert_allclose(arr.grad.numpy(), fd, rtol=2e-2, atol=2e-2)
        assert np.abs(fd).max() > 0.1  # the check is not trivially zero
