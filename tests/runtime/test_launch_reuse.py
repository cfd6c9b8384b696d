"""A plain ``launch`` with unchanged arguments reuses its packed form, and only then."""

import gc
import weakref

import numpy as np
import pytest

import kdsl as wp
from kdsl.backends.base import CompiledKernel
from kdsl.ir import types as T
from kdsl.runtime.launch import launch_plan
from kdsl.runtime.launch_reuse import LaunchReuse
from kdsl.testing.cases.programs import make_programs

BACKENDS = ["cpu", "interp"]


#: y = a * x + y (the seed programs' saxpy, a fresh kernel object for this module).
axpy = make_programs()["saxpy"]


@wp.kernel
def fill_index(out: wp.array2d(dtype=wp.int32)):
    i, j = wp.tid()
    out[i, j] = i * 100 + j


@wp.kernel
def reciprocal(x: float, out: wp.array(dtype=float)):
    out[0] = 1.0 / x


@wp.kernel
def put_vec(v: wp.vec3, out: wp.array(dtype=wp.vec3)):
    out[0] = v


@wp.struct
class Params:
    scale: float
    data: wp.array(dtype=float)


@wp.kernel
def scaled(p: Params, out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = p.scale * p.data[i]


def _reuse(kernel, backend):
    return launch_plan(kernel, "cpu", backend).reuse


def _launch_n(kernel, dim, inputs, backend, n=3):
    for _ in range(n):
        wp.launch(kernel, dim=dim, inputs=inputs, device="cpu", backend=backend)


@pytest.mark.parametrize("backend", BACKENDS)
def test_unchanged_arguments_reuse_the_packed_launch(backend):
    x = wp.array(np.arange(8, dtype=np.float32), device="cpu")
    y = wp.zeros(8, dtype=float, device="cpu")
    a = 2.0
    _launch_n(axpy, 8, [x, y, a], backend, n=4)
    np.testing.assert_array_equal(y.numpy(), 8 * np.arange(8, dtype=np.float32))
    if backend == "cpu":  # interp packs nothing: it never prepares
        assert _reuse(axpy, backend).hits >= 2


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_new_array_or_scalar_is_packed_afresh(backend):
    x = wp.array(np.ones(4, dtype=np.float32), device="cpu")
    y1 = wp.zeros(4, dtype=float, device="cpu")
    _launch_n(axpy, 4, [x, y1, 1.0], backend)
    y2 = wp.zeros(4, dtype=float, device="cpu")  # another array in the same place
    wp.launch(axpy, dim=4, inputs=[x, y2, 1.0], device="cpu", backend=backend)
    np.testing.assert_array_equal(y2.numpy(), np.ones(4))
    wp.launch(axpy, dim=4, inputs=[x, y2, 5.0], device="cpu", backend=backend)
    np.testing.assert_array_equal(y2.numpy(), np.full(4, 6.0))
    np.testing.assert_array_equal(y1.numpy(), np.full(4, 3.0))  # untouched since


@pytest.mark.parametrize("backend", BACKENDS)
def test_ping_pong_buffers_each_get_their_own_entry(backend):
    x = wp.array(np.ones(4, dtype=np.float32), device="cpu")
    y = wp.array(np.ones(4, dtype=np.float32), device="cpu")
    for _ in range(3):  # y += x then x += y: Fibonacci in both buffers
        wp.launch(axpy, dim=4, inputs=[x, y, 1.0], device="cpu", backend=backend)
        wp.launch(axpy, dim=4, inputs=[y, x, 1.0], device="cpu", backend=backend)
    assert x.numpy()[0] == 21.0 and y.numpy()[0] == 13.0


def test_signed_zero_is_a_different_scalar():
    out = wp.zeros(1, dtype=float, device="cpu")
    _launch_n(reciprocal, 1, [0.0, out], "cpu")
    assert out.numpy()[0] == np.inf
    wp.launch(reciprocal, dim=1, inputs=[-0.0, out], device="cpu")
    assert out.numpy()[0] == -np.inf


def test_a_numpy_array_reshaped_in_place_is_packed_afresh():
    out = np.zeros((4, 4), dtype=np.int32)
    _launch_n(fill_index, (4, 4), [out], "cpu")
    out.shape = (2, 8)  # the same object, another shape and strides
    wp.launch(fill_index, dim=(2, 8), inputs=[out], device="cpu")
    np.testing.assert_array_equal(out, np.add.outer(np.arange(2) * 100, np.arange(8)))


def test_a_vector_mutated_in_place_is_packed_afresh():
    out = wp.zeros(1, dtype=wp.vec3, device="cpu")
    v = wp.vec3(1.0, 2.0, 3.0)
    _launch_n(put_vec, 1, [v, out], "cpu")
    v[1] = 7.0
    wp.launch(put_vec, dim=1, inputs=[v, out], device="cpu")
    assert out.numpy()[0].tolist() == [1.0, 7.0, 3.0]


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_mutated_struct_is_packed_afresh(backend):
    p = Params()
    p.scale = 2.0
    p.data = wp.array(np.ones(3, dtype=np.float32), device="cpu")
    out = wp.zeros(3, dtype=float, device="cpu")
    _launch_n(scaled, 3, [p, out], backend)
    p.scale = 3.0
    wp.launch(scaled, dim=3, inputs=[p, out], device="cpu", backend=backend)
    np.testing.assert_array_equal(out.numpy(), np.full(3, 3.0))
    p.data = wp.array(np.full(3, 2.0, dtype=np.float32), device="cpu")
    wp.launch(scaled, dim=3, inputs=[p, out], device="cpu", backend=backend)
    np.testing.assert_array_equal(out.numpy(), np.full(3, 6.0))
    assert not _reuse(scaled, backend).enabled


def test_reuse_never_keeps_an_array_alive():
    x = wp.array(np.ones(4, dtype=np.float32), device="cpu")
    y = wp.zeros(4, dtype=float, device="cpu")
    _launch_n(axpy, 4, [x, y, 1.0], "cpu")
    assert _reuse(axpy, "cpu").hits >= 1
    buf = weakref.ref(y._buf)
    del y
    gc.collect()
    assert buf() is None
    # The entry of the dead buffer is refused, even if its id is taken again.
    z = wp.zeros(4, dtype=float, device="cpu")
    _launch_n(axpy, 4, [x, z, 1.0], "cpu")
    np.testing.assert_array_equal(z.numpy(), np.full(4, 3.0))


class _CountingBackend:
    """Records what ``LaunchReuse`` asks of a backend."""

    def __init__(self):
        self.launches, self.prepared, self.runs = 0, [], 0

    def launch(self, compiled, dims, args, stream):
        self.launches += 1

    def prepare_reusable(self, compiled, dims, args, stream):
        self.prepared.append((dims, stream))

        def run():
            self.runs += 1

        return run


def test_a_different_stream_or_grid_is_another_entry():
    backend = _CountingBackend()
    reuse = LaunchReuse(backend, CompiledKernel("fake", "k", None), [T.ArrayType(T.F32, 1)])
    buf = np.zeros(4, np.float32)
    s1, s2 = object(), object()
    for _ in range(3):
        reuse.launch((4,), [buf], s1)
    assert backend.prepared == [((4,), s1)] and backend.runs == 2
    reuse.launch((4,), [buf], s2)
    reuse.launch((4,), [buf], s2)
    reuse.launch((2,), [buf], s1)
    reuse.launch((2,), [buf], s1)
    assert backend.prepared == [((4,), s1), ((4,), s2), ((2,), s1)]
    assert backend.launches == 3  # each key's first sighting


def test_a_backend_without_prepare_reusable_launches_plainly():
    interp = launch_plan(axpy, "cpu", "interp")
    x = wp.array(np.ones(2, dtype=np.float32), device="cpu")
    y = wp.zeros(2, dtype=float, device="cpu")
    _launch_n(axpy, 2, [x, y, 1.0], "interp", n=4)
    assert interp.reuse.hits == 0 and not interp.reuse.entries
    np.testing.assert_array_equal(y.numpy(), np.full(2, 4.0))


@pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")
def test_cuda_reuse_and_its_guards():
    dev = "cuda:0"
    x = wp.array(np.arange(4, dtype=np.float32), device=dev)
    y = wp.zeros(4, dtype=float, device=dev)
    for _ in range(3):  # the second and third launches reuse the packed parameters
        wp.launch(axpy, dim=4, inputs=[x, y, 1.0], device=dev)
    assert launch_plan(axpy, dev, None).reuse.hits >= 1
    np.testing.assert_array_equal(y.numpy(), 3 * np.arange(4))
    z = wp.zeros(4, dtype=float, device=dev)  # another array: packed afresh
    wp.launch(axpy, dim=4, inputs=[x, z, -0.0], device=dev)
    wp.launch(axpy, dim=4, inputs=[x, z, 2.0], device=dev)  # another scalar
    np.testing.assert_array_equal(z.numpy(), 2 * np.arange(4))
    s = wp.Stream(dev)  # another stream: another key, and the launch goes there
    with wp.ScopedStream(s):
        for _ in range(3):
            wp.launch(axpy, dim=4, inputs=[x, z, 1.0], device=dev)
    s.synchronize()
    np.testing.assert_array_equal(z.numpy(), 5 * np.arange(4))
    entries = launch_plan(axpy, dev, None).reuse.entries  # keyed by the stream's id
    assert any(key[1] == id(s) and entry[2] is s for key, entry in entries.items())


@wp.kernel
def set_to(t: float, out: wp.array(dtype=float)):
    out[wp.tid()] = t


@pytest.mark.parametrize("backend", ["cpu"])  # the backend that prepares launches
def test_new_keys_in_a_row_bypass_the_tables_and_keying_resumes(backend, monkeypatch):
    from kdsl.runtime import launch_reuse

    monkeypatch.setattr(launch_reuse, "MISS_STREAK", 4)
    monkeypatch.setattr(launch_reuse, "BYPASS", 5)
    # A new array at every step (a changing scalar alone is patched in place instead).
    outs = [wp.zeros(3, dtype=float, device="cpu") for _ in range(9)]
    wp.launch(set_to, 3, inputs=[0.5, outs[0]], backend=backend)
    reuse = launch_plan(set_to, "cpu", backend).reuse
    assert reuse.bypass == 0 and reuse.misses == 1  # the first key was new
    for step in range(1, 4):  # three more new keys
        wp.launch(set_to, 3, inputs=[0.5 + step, outs[step]], backend=backend)
    assert reuse.bypass == 5 and reuse.misses == 0
    for step in range(4, 9):  # bypassed: no keys, right values
        wp.launch(set_to, 3, inputs=[0.5 + step, outs[step]], backend=backend)
        np.testing.assert_array_equal(outs[step].numpy(), np.full(3, 0.5 + step))
    assert reuse.bypass == 0 and not reuse.patches
    out = outs[0]
    hits = reuse.hits
    for _ in range(3):  # keying again: a recurring key is prepared and reused
        wp.launch(set_to, 3, inputs=[7.0, out], backend=backend)
    assert reuse.hits > hits and reuse.misses == 0
    np.testing.assert_array_equal(out.numpy(), np.full(3, 7.0))


@pytest.mark.parametrize("backend", ["cpu"])
def test_a_cycle_of_argument_sets_is_learnt_without_a_bypass(backend):
    outs = [wp.zeros(2, dtype=float, device="cpu") for _ in range(100)]
    for _ in range(3):  # a taped flight's pattern: 100 argument sets, over and over
        for i, o in enumerate(outs):
            wp.launch(set_to, 2, inputs=[float(i) + 0.25, o], backend=backend)
    reuse = launch_plan(set_to, "cpu", backend).reuse
    assert reuse.bypass == 0 and reuse.hits >= 100
    assert [o.numpy()[0] for o in outs] == [i + 0.25 for i in range(100)]
