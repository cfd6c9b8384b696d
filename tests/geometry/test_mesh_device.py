"""A mesh's id launched on another device than the mesh's is refused before the kernel
runs, with a message naming the mesh and both devices (``kdsl.runtime.objects``)."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from tests.geometry.mesh_reference import icosphere


@wp.kernel
def closest_face(mesh: wp.uint64, xs: wp.array(dtype=wp.vec3), face: wp.array(dtype=int)):
    i = wp.tid()
    q = wp.mesh_query_point_no_sign(mesh, xs[i], 10.0)
    face[i] = q.face


def _mesh(device: str) -> wp.Mesh:
    pts, faces = icosphere(0)
    return wp.Mesh(wp.array(pts, dtype=wp.vec3, device=device),
                   wp.array(faces, dtype=wp.int32, device=device))  # fmt: skip


def _inputs(mesh_id: int, device: str) -> list:
    xs = wp.array(np.full((2, 3), 2.0, np.float32), dtype=wp.vec3, device=device)
    return [mesh_id, xs, wp.zeros(2, dtype=int, device=device)]


def test_cpu_mesh_refused_when_its_record_says_another_device(monkeypatch):
    """On a machine without a GPU: the cpu mesh's table entry is made to say cuda:0."""
    from kdsl.runtime import objects

    mesh = _mesh("cpu")
    face = wp.zeros(2, dtype=int)
    inputs = _inputs(mesh.id, "cpu")
    inputs[2] = face
    wp.launch(closest_face, dim=2, inputs=inputs)  # its own device: fine
    assert (face.numpy() >= 0).all()
    owner, kind, _ = objects.owner_of(mesh.id)
    assert owner is mesh and kind == "mesh"
    monkeypatch.setitem(objects._owners, mesh.id, (objects._owners[mesh.id][0], kind, "cuda:0"))
    with pytest.raises(wp.KdslLaunchError, match=r"is the id of a mesh on device 'cuda:0', "
                                                 r"not on 'cpu'") as err:  # fmt: skip
        wp.launch(closest_face, dim=2, inputs=inputs)
    assert "closest_face" in str(err.value)  # the kernel and the argument are named
    assert "mesh" in str(err.value)


@pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")
@pytest.mark.parametrize(("mesh_device", "launch_device"), [("cuda:0", "cpu"), ("cpu", "cuda:0")])
def test_mesh_on_another_device_refused(mesh_device, launch_device):
    mesh = _mesh(mesh_device)
    with pytest.raises(wp.KdslLaunchError,
                       match=f"is the id of a mesh on device '{mesh_device}', "
                             f"not on '{launch_device}'"):  # fmt: skip
        wp.launch(closest_face, dim=2, inputs=_inputs(mesh.id, launch_device),
                  device=launch_device)  # fmt: skip
