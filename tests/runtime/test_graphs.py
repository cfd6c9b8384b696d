"""Graph capture and replay (issue 17 item 1): Warp's capture API on cpu and cuda.

The cuda variants need a GPU (skipped without one); every cpu test runs in CI.
"""

import gc

import numpy as np
import pytest

import kdsl as wp

CUDA = pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")
DEVICES = ["cpu", pytest.param("cuda:0", marks=CUDA)]


@wp.kernel
def add_scaled(a: wp.array(dtype=float), b: wp.array(dtype=float), s: float):
    i = wp.tid()
    a[i] = a[i] + s * b[i]


@wp.kernel
def relax(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    n = x.shape[0]
    left = x[wp.max(i - 1, 0)]
    right = x[wp.min(i + 1, n - 1)]
    y[i] = 0.25 * left + 0.5 * x[i] + 0.25 * right


@wp.kernel
def count_down(counter: wp.array(dtype=wp.int32), cond: wp.array(dtype=wp.int32),
               total: wp.array(dtype=float)):  # fmt: skip
    counter[0] = counter[0] - 1
    total[0] = total[0] + 1.0
    if counter[0] <= 0:
        cond[0] = 0


def _step(x, y, b, n):
    """A 100-kernel simulation step: 50 relax/update pairs."""
    for k in range(50):
        wp.launch(relax, dim=n, inputs=[x, y], device=x.device)
        wp.launch(add_scaled, dim=n, inputs=[x, y, 0.01 * (k % 3)], device=x.device)
        wp.launch(add_scaled, dim=n, inputs=[x, b, -0.001], device=x.device) if k == 49 else None


def _state(device, n=257):
    rng = np.random.default_rng(5)
    x = wp.array(rng.random(n, dtype=np.float32), device=device)
    y = wp.zeros(n, dtype=float, device=device)
    b = wp.array(rng.random(n, dtype=np.float32), device=device)
    return x, y, b


@pytest.mark.parametrize("device", DEVICES)
def test_hundred_kernel_step_as_one_graph_matches_plain_launches(device):
    n = 257
    x1, y1, b1 = _state(device, n)
    x2, y2, b2 = _state(device, n)
    with wp.ScopedCapture(device=device) as capture:
        _step(x2, y2, b2, n)
    graph = capture.graph
    assert isinstance(graph, wp.Graph) and graph.device == wp.get_device(device)
    for _ in range(4):
        _step(x1, y1, b1, n)
        wp.capture_launch(graph)
    np.testing.assert_array_equal(x1.numpy(), x2.numpy())
    np.testing.assert_array_equal(y1.numpy(), y2.numpy())


@pytest.mark.parametrize("device", DEVICES)
def test_capture_records_without_running(device):
    a = wp.zeros(4, dtype=float, device=device)
    b = wp.full(4, 2.0, dtype=float, device=device)
    wp.capture_begin(device=device)
    wp.launch(add_scaled, dim=4, inputs=[a, b, 1.0], device=device)
    graph = wp.capture_end(device=device)
    np.testing.assert_array_equal(a.numpy(), 0.0)
    wp.capture_launch(graph)
    wp.capture_launch(graph)
    np.testing.assert_array_equal(a.numpy(), 4.0)


@pytest.mark.parametrize("device", DEVICES)
def test_copies_fills_and_allocations_inside_a_capture(device):
    src = wp.array(np.arange(6, dtype=np.float32), device=device)
    out = wp.zeros(6, dtype=float, device=device)
    with wp.ScopedCapture(device=device) as capture:
        tmp = wp.zeros(6, dtype=float, device=device)  # from the pool, owned by the graph
        wp.launch(add_scaled, dim=6, inputs=[tmp, src, 2.0], device=device)
        wp.copy(out, tmp)
        src.zero_()
    del tmp
    gc.collect()
    wp.capture_launch(capture.graph)
    np.testing.assert_array_equal(out.numpy(), 2.0 * np.arange(6))
    np.testing.assert_array_equal(src.numpy(), 0.0)
    src.fill_(1.0)
    wp.capture_launch(capture.graph)  # tmp is zeroed again at each replay
    np.testing.assert_array_equal(out.numpy(), 2.0)


@pytest.mark.parametrize("device", DEVICES)
def test_capture_while_iterates_until_a_device_condition_flips(device):
    counter = wp.array([5], dtype=wp.int32, device=device)
    cond = wp.array([1], dtype=wp.int32, device=device)
    total = wp.zeros(1, dtype=float, device=device)

    def body():
        wp.launch(count_down, dim=1, inputs=[counter, cond, total], device=device)

    with wp.ScopedCapture(device=device) as capture:
        wp.capture_while(cond, body)
    assert total.numpy()[0] == 0.0
    wp.capture_launch(capture.graph)
    assert total.numpy()[0] == 5.0 and cond.numpy()[0] == 0
    counter.assign(np.array([3], dtype=np.int32))
    cond.fill_(1)
    wp.capture_launch(capture.graph)
    assert total.numpy()[0] == 8.0
    # Outside a capture it runs at once.
    counter.fill_(2)
    cond.fill_(1)
    wp.capture_while(cond, body)
    assert total.numpy()[0] == 10.0


@pytest.mark.parametrize("device", DEVICES)
def test_capture_if_chooses_at_each_replay(device):
    cond = wp.array([1], dtype=wp.int32, device=device)
    a = wp.zeros(1, dtype=float, device=device)
    one = wp.ones(1, dtype=float, device=device)

    def add(s):
        wp.launch(add_scaled, dim=1, inputs=[a, one, s], device=device)

    with wp.ScopedCapture(device=device) as inner:
        add(100.0)
    with wp.ScopedCapture(device=device) as capture:
        add(1.0)
        wp.capture_if(cond, on_true=add, on_false=inner.graph, s=10.0)
    wp.capture_launch(capture.graph)
    assert a.numpy()[0] == 11.0
    cond.zero_()
    wp.capture_launch(capture.graph)
    assert a.numpy()[0] == 112.0
    wp.capture_if(cond, on_true=add, s=1000.0)  # no capture: runs at once (false: nothing)
    assert a.numpy()[0] == 112.0
    assert wp.is_conditional_graph_supported() is False


@pytest.mark.parametrize("device", DEVICES)
def test_graph_launched_inside_a_capture_is_appended(device):
    a = wp.zeros(2, dtype=float, device=device)
    one = wp.ones(2, dtype=float, device=device)
    with wp.ScopedCapture(device=device) as inner:
        wp.launch(add_scaled, dim=2, inputs=[a, one, 1.0], device=device)
    with wp.ScopedCapture(device=device) as outer:
        wp.capture_launch(inner.graph)
        wp.capture_launch(inner.graph)
    wp.capture_launch(outer.graph)
    np.testing.assert_array_equal(a.numpy(), 2.0)


@pytest.mark.parametrize("device", DEVICES)
def test_host_reads_and_syncs_inside_a_capture_are_refused_and_the_capture_goes_on(device):
    a = wp.zeros(3, dtype=float, device=device)
    one = wp.ones(3, dtype=float, device=device)
    with wp.ScopedCapture(device=device) as capture:
        wp.launch(add_scaled, dim=3, inputs=[a, one, 1.0], device=device)
        with pytest.raises(wp.KdslRuntimeError, match="graph capture is open"):
            a.numpy()
        with pytest.raises(wp.KdslRuntimeError, match="host synchronization"):
            wp.synchronize()
        with pytest.raises(wp.KdslRuntimeError, match="host synchronization"):
            wp.synchronize_device(device)
        wp.launch(add_scaled, dim=3, inputs=[a, one, 1.0], device=device)
    wp.capture_launch(capture.graph)
    np.testing.assert_array_equal(a.numpy(), 2.0)


@pytest.mark.parametrize("device", DEVICES)
def test_second_capture_on_the_same_stream_is_refused(device):
    wp.capture_begin(device=device)
    try:
        with pytest.raises(wp.KdslRuntimeError, match="already open"):
            wp.capture_begin(device=device)
    finally:
        graph = wp.capture_end(device=device)
    assert graph.num_nodes <= 1
    with pytest.raises(wp.KdslRuntimeError, match="no graph capture is open"):
        wp.capture_end(device=device)


@pytest.mark.parametrize("device", DEVICES)
def test_error_inside_scoped_capture_ends_the_capture(device):
    a = wp.zeros(3, dtype=float, device=device)
    with pytest.raises(ZeroDivisionError), wp.ScopedCapture(device=device):
        wp.launch(add_scaled, dim=3, inputs=[a, a, 1.0], device=device)
        1 / 0  # noqa: B018
    # Nothing is open any more: plain launches run, and a new capture can begin.
    wp.launch(add_scaled, dim=3, inputs=[a, wp.ones(3, dtype=float, device=device), 1.0],
              device=device)  # fmt: skip
    np.testing.assert_array_equal(a.numpy(), 1.0)
    with wp.ScopedCapture(device=device) as capture:
        pass
    wp.capture_launch(capture.graph)


@pytest.mark.parametrize("device", DEVICES)
def test_replaying_a_graph_whose_arrays_were_freed_is_refused(device):
    a = wp.zeros(3, dtype=float, device=device)
    b = wp.ones(3, dtype=float, device=device)
    view = a[1:]
    with wp.ScopedCapture(device=device) as capture:
        wp.launch(add_scaled, dim=2, inputs=[view, b[1:], 1.0], device=device)
    del view
    gc.collect()
    wp.capture_launch(capture.graph)  # a still holds the memory the view pointed into
    np.testing.assert_array_equal(a.numpy(), [0.0, 1.0, 1.0])
    del a
    gc.collect()
    with pytest.raises(wp.KdslRuntimeError, match="freed after the capture"):
        wp.capture_launch(capture.graph)


@pytest.mark.parametrize("device", DEVICES)
def test_capture_misuse_gives_kdsl_errors(device):
    with pytest.raises(wp.KdslError, match=r"takes a kdsl\.Graph"):
        wp.capture_launch("graph")
    with pytest.raises(wp.KdslError, match="array of int32"):
        wp.capture_if(wp.zeros(1, dtype=float, device=device), on_true=lambda: None)
    with pytest.raises(wp.KdslCapabilityError, match="cannot serialize graphs"):
        wp.capture_save(None, "g.wrp")
    with pytest.raises(wp.KdslCapabilityError, match="cannot serialize graphs"):
        wp.capture_load("g.wrp", device=device)
    with pytest.raises(wp.KdslCapabilityError, match="external"):
        wp.capture_begin(device=device, external=True)


def test_repeated_launches_in_a_capture_skip_the_argument_checks():
    a = wp.zeros(4, dtype=float, device="cpu")
    b = wp.ones(4, dtype=float, device="cpu")
    s = 1.0
    with wp.ScopedCapture(device="cpu") as capture:
        wp.launch(add_scaled, dim=4, inputs=[a, b, s], device="cpu")
        rec = wp.runtime.graphs.state.ACTIVE[-1]
        assert len(rec.args_cache) == 1
        wp.launch(add_scaled, dim=4, inputs=[a, b, s], device="cpu")
        assert len(rec.args_cache) == 1  # the same objects: reused, not converted again
        with pytest.raises(wp.KdslLaunchError, match="argument 1"):
            wp.launch(add_scaled, dim=4, inputs=[a, np.ones(4), s], device="cpu")
    assert rec.args_cache == {}
    wp.capture_launch(capture.graph)
    np.testing.assert_array_equal(a.numpy(), 2.0)


def test_cpu_capture_records_a_tape_backward():
    x = wp.array(np.arange(4, dtype=np.float32), device="cpu", requires_grad=True)
    y = wp.zeros(4, dtype=float, device="cpu", requires_grad=True)
    with wp.ScopedCapture(device="cpu") as capture:
        tape = wp.Tape()
        with tape:
            wp.launch(add_scaled, dim=4, inputs=[y, x, 3.0], device="cpu")
        tape.backward(grads={y: wp.ones(4, dtype=float, device="cpu")})
    assert np.all(x.grad.numpy() == 0.0)
    wp.capture_launch(capture.graph)
    np.testing.assert_array_equal(x.grad.numpy(), 3.0)


@CUDA
def test_cuda_graph_on_another_device_stream_is_refused():
    if wp.get_cuda_device_count() < 2:
        pytest.skip("needs two CUDA devices")
    a = wp.zeros(2, dtype=float, device="cuda:0")
    with wp.ScopedCapture(device="cuda:0") as capture:
        wp.launch(add_scaled, dim=2, inputs=[a, a, 1.0], device="cuda:0")
    with pytest.raises(wp.KdslRuntimeError, match="cannot run on a stream"):
        wp.capture_launch(capture.graph, stream=wp.get_stream("cuda:1"))


@CUDA
def test_cuda_capture_on_a_private_stream_and_host_copies_refused():
    s = wp.Stream("cuda:0")
    a = wp.zeros(4, dtype=float, device="cuda:0")
    one = wp.ones(4, dtype=float, device="cuda:0")
    host = wp.zeros(4, dtype=float, device="cpu")
    with wp.ScopedStream(s):
        with wp.ScopedCapture(stream=s) as capture:
            assert s.is_capturing
            wp.launch(add_scaled, dim=4, inputs=[a, one, 1.0])
            with pytest.raises(wp.KdslRuntimeError, match="pageable"):
                wp.copy(host, a)
            with pytest.raises(wp.KdslRuntimeError, match="non-uniform"):
                wp.zeros(2, dtype=wp.vec3, device="cuda:0").fill_(wp.vec3(1.0, 2.0, 3.0))
        assert not s.is_capturing
        wp.capture_launch(capture.graph, stream=s)
    wp.synchronize_stream(s)  # ScopedStream does not sync on exit (as in Warp)
    np.testing.assert_array_equal(a.numpy(), 1.0)


@CUDA
def test_cuda_debug_build_is_refused_in_a_capture(monkeypatch):
    monkeypatch.setattr(wp.config, "mode", "debug")
    a = wp.zeros(2, dtype=float, device="cuda:0")
    refused = pytest.raises(wp.KdslRuntimeError, match="debug checks")
    with wp.ScopedCapture(device="cuda:0") as capture, refused:
        wp.launch(add_scaled, dim=2, inputs=[a, a, 1.0], device="cuda:0")
    wp.capture_launch(capture.graph)
    np.testing.assert_array_equal(a.numpy(), 0.0)
