"""``LaunchReuse.relaunch``: the very argument objects of the last launch skip conversion.

Each test changes one thing the shortcut must notice (a scalar, an array object, the
grid, a freed array, a foreign array, a mutable vector) and checks the kernel sees it;
the shortcut itself is observed through ``reuse.same`` and ``reuse.hits``.
"""

import gc

import numpy as np
import pytest

import kdsl as wp
from kdsl.runtime.launch import launch_plan
from kdsl.testing.cases.programs import make_programs

BACKENDS = ["cpu", "interp"]

#: y = a * x + y (a fresh kernel object for this module).
axpy = make_programs()["saxpy"]


@wp.kernel
def put_vec(v: wp.vec3, out: wp.array(dtype=wp.vec3)):
    out[0] = v


@wp.kernel
def scale_by(n: wp.uint64, out: wp.array(dtype=float)):
    out[0] = float(n)


def _reuse(kernel, backend):
    return launch_plan(kernel, "cpu", backend).reuse


def _arrays(n=4):
    return wp.array(np.ones(n, np.float32)), wp.zeros(n, dtype=float)


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_same_objects_relaunch_without_conversion(backend):
    x, y = _arrays()
    a = 2.0
    for _ in range(3):  # the second launch prepares, the third remembers its objects
        wp.launch(axpy, dim=4, inputs=[x, y, a], device="cpu", backend=backend)
    reuse = _reuse(axpy, backend)
    if reuse.same is None:
        pytest.skip(f"the {backend} backend does not prepare reusable launches")
    hits = reuse.hits
    for _ in range(4):
        wp.launch(axpy, dim=4, inputs=[x, y, a], device="cpu", backend=backend)
    assert reuse.hits == hits + 4 and reuse.same is not None
    assert y.numpy().tolist() == [14.0] * 4


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_new_scalar_array_or_grid_is_seen(backend):
    x, y = _arrays()
    for _ in range(3):
        wp.launch(axpy, dim=4, inputs=[x, y, 1.0], device="cpu", backend=backend)
    assert y.numpy().tolist() == [3.0] * 4
    wp.launch(axpy, dim=4, inputs=[x, y, 10.0], device="cpu", backend=backend)
    assert y.numpy().tolist() == [13.0] * 4
    x2 = wp.array(np.full(4, 2.0, np.float32))
    wp.launch(axpy, dim=4, inputs=[x2, y, 10.0], device="cpu", backend=backend)
    assert y.numpy().tolist() == [33.0] * 4
    wp.launch(axpy, dim=2, inputs=[x2, y, 10.0], device="cpu", backend=backend)
    assert y.numpy().tolist() == [53.0, 53.0, 33.0, 33.0]
    s = np.float32(0.5)
    for _ in range(3):
        wp.launch(axpy, dim=4, inputs=[x2, y, s], device="cpu", backend=backend)
    assert y.numpy().tolist() == [56.0, 56.0, 36.0, 36.0]


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_freed_array_is_never_matched_by_identity(backend):
    y = wp.zeros(4, dtype=float)
    for k in range(6):  # new x objects, maybe at a freed one's address
        x = wp.array(np.full(4, float(k), np.float32))
        for _ in range(3):
            wp.launch(axpy, dim=4, inputs=[x, y, 1.0], device="cpu", backend=backend)
        del x
        gc.collect()
    assert y.numpy().tolist() == [3.0 * sum(range(6))] * 4


@pytest.mark.parametrize("backend", BACKENDS)
def test_mutable_or_foreign_arguments_never_take_the_shortcut(backend):
    out = wp.zeros(1, dtype=wp.vec3)
    v = wp.vec3(1.0, 2.0, 3.0)
    for k in range(5):
        v[0] = float(k)  # mutated in place: the same object, a new value
        wp.launch(put_vec, dim=1, inputs=[v, out], device="cpu", backend=backend)
        assert out.numpy()[0].tolist() == [float(k), 2.0, 3.0]
    same = _reuse(put_vec, backend).same  # a patchable launch's record never holds it
    assert same is None or all(h is not v for h in same[2])
    y = wp.zeros(4, dtype=float)
    host = np.ones(4, np.float32)  # a NumPy array may be refilled or reshaped in place
    for _ in range(3):
        wp.launch(axpy, dim=4, inputs=[host, y, 1.0], device="cpu", backend=backend)
    assert _reuse(axpy, backend).same is None
    o = wp.zeros(1, dtype=float)
    for _ in range(3):
        wp.launch(scale_by, dim=1, inputs=[7, o], device="cpu", backend=backend)
    assert o.numpy().tolist() == [7.0] and _reuse(scale_by, backend).same is None


@pytest.mark.parametrize("backend", BACKENDS)
def test_relaunches_are_recorded_on_an_active_tape(backend):
    x, y = _arrays()
    x.requires_grad = y.requires_grad = True
    for _ in range(3):
        wp.launch(axpy, dim=4, inputs=[x, y, 1.0], device="cpu", backend=backend)
    tape = wp.Tape()
    with tape:
        for _ in range(3):
            wp.launch(axpy, dim=4, inputs=[x, y, 1.0], device="cpu", backend=backend)
    assert len(tape.launches) == 3
    assert tape.launches[-1].metadata["caller"]["file"] == __file__


@pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")
def test_cuda_relaunch_follows_the_current_stream():
    x = wp.array(np.ones(4, np.float32), device="cuda:0")
    y = wp.zeros(4, dtype=float, device="cuda:0")
    for _ in range(3):
        wp.launch(axpy, dim=4, inputs=[x, y, 1.0], device="cuda:0")
    reuse = launch_plan(axpy, "cuda:0", None).reuse
    assert reuse.same is not None and reuse.same[1] is wp.get_stream("cuda:0")
    s = wp.Stream("cuda:0")
    with wp.ScopedStream(s):
        wp.launch(axpy, dim=4, inputs=[x, y, 1.0], device="cuda:0")
        assert reuse.same is None or reuse.same[1] is s
    wp.synchronize()
    assert y.numpy().tolist() == [4.0] * 4
