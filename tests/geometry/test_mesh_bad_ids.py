"""A freed, null or never-built mesh id passed to a debug kernel stops it with a clear
``KdslRuntimeError``: the query's line inside the library, then each call it came
through out to the line of the user's kernel, and never a crash. An id that cannot be
a record's address (small, unaligned, beyond user space) is refused without being
read (``kdsl.ir.ops_debug.plausible_record_id``)."""

from __future__ import annotations

import gc
import re

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslRuntimeError
from tests.geometry.mesh_targets import BACKENDS, device_of

V3 = wp.vec3


@wp.kernel(debug=True)
def closest_faces(mesh: wp.uint64, xs: wp.array(dtype=V3), face: wp.array(dtype=int)):
    i = wp.tid()
    q = wp.mesh_query_point_no_sign(mesh, xs[i], 10.0)  # THE QUERY
    face[i] = q.face


with open(__file__) as _source:
    QUERY_LINE = next(n for n, line in enumerate(_source, 1) if "# THE QUERY" in line)


def _mesh(device: str) -> wp.Mesh:
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    return wp.Mesh(wp.array(pts, dtype=V3, device=device),
                   wp.array([0, 1, 2], dtype=wp.int32, device=device))  # fmt: skip


def _launch(mesh_id: int, backend: str) -> np.ndarray:
    dev = device_of(backend)
    xs = wp.array(np.full((2, 3), 0.2, np.float32), dtype=V3, device=dev)
    face = wp.full(2, -1, dtype=int, device=dev)
    wp.launch(closest_faces, dim=2, inputs=[mesh_id, xs, face], backend=backend, device=dev)
    return face.numpy()


def _names_the_users_line(err: KdslRuntimeError) -> None:
    text = str(err)
    assert "as a MeshRecord, but no live object of that kind has this id" in text
    assert re.search(r'File ".*kdsl[/\\]stdlib[/\\]mesh\.py", line \d+', text)
    assert f'called from File "{__file__}", line {QUERY_LINE}' in text
    assert "q = wp.mesh_query_point_no_sign(mesh, xs[i], 10.0)" in text  # the source line


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_freed_mesh_id_names_the_kernels_line(backend):
    mesh = _mesh(device_of(backend))
    assert list(_launch(mesh.id, backend)) == [0, 0]
    stale = mesh.id
    del mesh
    gc.collect()
    with pytest.raises(KdslRuntimeError) as err:
        _launch(stale, backend)
    _names_the_users_line(err.value)


def _refused(bad: int, backend: str) -> None:
    with pytest.raises(KdslRuntimeError) as err:
        _launch(bad, backend)
    _names_the_users_line(err.value)
    assert f"{bad:#x}" in str(err.value) or (bad == 0 and "null id" in str(err.value))


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize(
    "bad", [0, 3, 12345, (1 << 20) + 8, 1 << 50, (1 << 64) - 1],
    ids=["null", "small", "odd", "unaligned", "beyond", "all-ones"],
)  # fmt: skip
def test_a_never_built_id_is_an_error_not_a_crash(backend, bad):
    _refused(bad, backend)


@pytest.mark.parametrize("bad", [1 << 20, 1 << 40], ids=["low", "high"])
def test_the_interpreter_reads_no_address_outside_its_record_memory(bad):
    # plausible (aligned, in user space) but unmapped: only the interpreter knows the
    # slabs' bounds; compiled cpu and cuda code would read it (debug mode's limit)
    _refused(bad, "interp")


def test_the_checked_query_compiles_for_cuda():
    pytest.importorskip("cupy_backends.cuda.libs.nvrtc")
    from kdsl.backends.cuda import nvrtc
    from kdsl.backends.cuda.lower import generate
    from kdsl.passes import DEFAULT_PIPELINE, run_pipeline

    m = closest_faces.build_module()
    run_pipeline(m, DEFAULT_PIPELINE + ",bounds-check")
    text = generate(m, [closest_faces.key], debug=True).text
    assert "65536ull" in text  # the id is checked before its tag is read
    assert nvrtc.compile_source(text, "sm_90").ptx
