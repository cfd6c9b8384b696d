"""``LaunchReuse.run_known``: a cycle of argument sets (a taped flight and its adjoints)
runs learnt launches keyed by the argument objects. Each test changes one thing the key
must notice and checks the kernel sees it; hits are counted through ``reuse.hits``."""

import gc
import itertools

import numpy as np
import pytest

import kdsl as wp
from kdsl.runtime.adjoint import adjoint_kernel
from kdsl.runtime.launch import launch_plan

cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")
DEVICES = ["cpu", pytest.param("cuda:0", marks=cuda)]


@wp.kernel
def step(x: wp.array(dtype=float), g: wp.vec3, s: float, k: int, y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = x[i] * s + g[0] + float(k)


@wp.kernel
def put(s: float, y: wp.array(dtype=float)):
    y[wp.tid()] = s


@wp.kernel
def total(x: wp.array(dtype=float), loss: wp.array(dtype=float)):
    i = wp.tid()
    wp.atomic_add(loss, 0, x[i])


def _cycle(device, xs, g, s, k, n=4):
    """Launch ``step`` on each neighbour pair: a cycle of argument sets."""
    for a, b in itertools.pairwise(xs):
        wp.launch(step, n, [a, g, s, k, b], device=device)


def _hits(kernel, device):
    return launch_plan(kernel, device, None).reuse.hits


def _arrays(device, count=4, n=4, grad=False):
    return [wp.full(n, 1.0, dtype=float, device=device, requires_grad=grad) for _ in range(count)]


@pytest.mark.parametrize("device", DEVICES)
def test_a_cycle_of_argument_sets_is_served_by_object_keys(device):
    xs = _arrays(device)
    g = wp.vec3(0.5, 0.0, 0.0)
    for _ in range(3):  # seen, prepared, learnt
        _cycle(device, xs, g, 2.0, 1)
    reuse = launch_plan(step, device, None).reuse
    assert reuse.tokens is not None and len(reuse.known) >= 3
    hits = reuse.hits
    _cycle(device, xs, g, 2.0, 1)
    assert reuse.hits == hits + 3
    # every launch ran: x0 = 1, x(k+1) = 2 x(k) + 1.5
    np.testing.assert_array_equal(xs[-1].numpy(), 2 * (2 * 3.5 + 1.5) + 1.5)


@pytest.mark.parametrize("device", DEVICES)
def test_changed_values_are_seen(device):
    xs = _arrays(device, count=2)
    g = wp.vec3(0.0, 0.0, 0.0)
    for _ in range(3):
        wp.launch(step, 4, [xs[0], g, 2.0, 1, xs[1]], device=device)
    cases = [  # (s, k, g[0]) and the expected y for x = 1
        (3.0, 1, 0.0, 4.0),
        (np.float32(3.0), 1, 0.0, 4.0),
        (3.0, np.int32(5), 0.0, 8.0),
        (3.0, 5, 0.25, 8.25),
        (-0.0, 0, 0.0, 0.0),
        (0.0, 0, 0.0, 0.0),
        (3, 2, 0.0, 5.0),  # an int for a float parameter, as the general path allows
    ]
    for s, k, g0, want in cases:
        for _ in range(3):
            g[0] = g0  # the same vector object, changed in place
            wp.launch(step, 4, [xs[0], g, s, k, xs[1]], device=device)
            np.testing.assert_array_equal(xs[1].numpy(), want)
    # signed zeros reach the kernel (-0.0 == 0.0, yet a launch must not reuse the other)
    for z in (0.0, -0.0, 0.0, np.float32(-0.0), -0.0):
        for _ in range(3):
            wp.launch(put, 4, [z, xs[1]], device=device)
            assert xs[1].numpy().tobytes() == np.full(4, z, np.float32).tobytes()


def test_wrong_kinds_still_fail_after_the_right_ones_were_learnt():
    xs = _arrays("cpu", count=2)
    g = wp.vec3(0.0, 0.0, 0.0)
    for _ in range(3):
        wp.launch(step, 4, [xs[0], g, 2.0, 1, xs[1]], device="cpu")
    with pytest.raises(wp.KdslLaunchError, match=r"argument 2 's'.*float64"):
        wp.launch(step, 4, [xs[0], g, np.float64(2.0), 1, xs[1]], device="cpu")
    with pytest.raises(wp.KdslLaunchError, match="argument 3 'k'"):
        wp.launch(step, 4, [xs[0], g, 2.0, 1.0, xs[1]], device="cpu")
    with pytest.raises(wp.KdslLaunchError, match="argument 3 'k'"):
        wp.launch(step, 4, [xs[0], g, 2.0, True, xs[1]], device="cpu")
    with pytest.raises(wp.KdslLaunchError, match="argument 0 'x'"):
        wp.launch(step, 4, [wp.zeros(4, dtype=wp.float64), g, 2.0, 1, xs[1]], device="cpu")


def test_a_freed_array_is_never_matched_by_identity():
    y = wp.zeros(4, dtype=float)
    g = wp.vec3(0.0, 0.0, 0.0)
    for k in range(8):  # new x objects, maybe at a freed one's address
        x = wp.full(4, float(k), dtype=float)
        for _ in range(3):
            wp.launch(step, 4, [x, g, 1.0, 0, y], device="cpu")
        np.testing.assert_array_equal(y.numpy(), float(k))
        del x
        gc.collect()


def _flight(device, xs, loss, s):
    tape = wp.Tape()
    with tape:
        _cycle(device, xs, wp.vec3(0.0, 0.0, 0.0), s, 0)
        wp.launch(total, 4, [xs[-1], loss], device=device)
    tape.backward(loss=loss)
    return tape


@pytest.mark.parametrize("device", DEVICES)
def test_taped_flights_reuse_adjoints_and_see_new_gradients(device):
    xs = _arrays(device, count=5, grad=True)
    loss = wp.zeros(1, dtype=float, device=device, requires_grad=True)
    adj_plan = launch_plan(adjoint_kernel(step), device, None)
    for s in (2.0, 2.0, 2.0, 2.0, 3.0):
        tape = _flight(device, xs, loss, s)
        np.testing.assert_allclose(xs[0].grad.numpy(), s**4)
        tape.zero()
    assert adj_plan.reuse.hits >= 4
    # a replaced gradient array is the one the adjoint writes
    fresh = wp.zeros(4, dtype=float, device=device)
    old = xs[0].grad
    xs[0].grad = fresh
    tape = _flight(device, xs, loss, 2.0)
    np.testing.assert_allclose(fresh.numpy(), 16.0)
    np.testing.assert_array_equal(old.numpy(), 0.0)
    tape.zero()


@pytest.mark.parametrize("device", DEVICES)
def test_retain_grad_changes_the_adjoint_launch(device):
    """grad_owned: with retain_grad the stored-to array keeps its gradient."""
    xs = _arrays(device, count=3, grad=True)
    loss = wp.zeros(1, dtype=float, device=device, requires_grad=True)
    for retain in (False, False, False, True, True, False):
        xs[1].retain_grad = retain
        tape = _flight(device, xs, loss, 2.0)
        np.testing.assert_allclose(xs[0].grad.numpy(), 4.0)
        assert np.all(xs[1].grad.numpy() == (2.0 if retain else 0.0))
        tape.zero()


@cuda
def test_streams_key_by_identity_cuda():
    """Each stream object has its own entries (the key holds its id, the entry the
    stream); launches on either give the right results."""
    dev = "cuda:0"
    xs = _arrays(dev, count=2)
    # The arrays are filled on the device's current stream; the launches go to others.
    wp.synchronize_device(dev)
    g = wp.vec3(0.0, 0.0, 0.0)
    streams = [wp.Stream(dev), wp.Stream(dev)]
    reuse = launch_plan(step, dev, None).reuse
    for k in range(4):
        for s in streams:
            for _ in range(3):
                wp.launch(step, 4, [xs[0], g, 2.0, k, xs[1]], device=dev, stream=s)
            s.synchronize()
            np.testing.assert_array_equal(xs[1].numpy(), 2.0 + k)
    stream_ids = {key[1] for key in reuse.known}
    assert {id(s) for s in streams} <= stream_ids
    assert all(entry[2] in streams for key, entry in reuse.known.items() if key[1] in
               {id(s) for s in streams})  # fmt: skip


@pytest.mark.parametrize("device", DEVICES)
def test_float_zero_arguments_key_a_launch_by_their_sign(device):
    """A zero by-value argument (a scene's damping 0.0) made afresh at every launch, on
    arrays that alternate (so ``relaunch`` cannot serve it), is served by ``run_known``;
    +0.0 and -0.0 keep their own entries, and a bad scalar is still refused with the
    kernel and parameter named."""
    xs = _arrays(device, count=3)
    g = wp.vec3(0.0, 0.0, 0.0)
    reuse = launch_plan(put, device, None).reuse
    # The stream a launch without one runs on: the key holds its id (None on the cpu).
    stream = wp.get_stream(device) if wp.get_device(device).is_cuda else None
    for z in (0.0, np.float32(0.0), -0.0, np.float32(-0.0), 0, -0.0, 0.0):
        for rep in range(4):  # seen, prepared, learnt, then served by the object key
            for y in xs[1:]:
                hits = reuse.hits
                wp.launch(put, 4, [type(z)(z), y], device=device)
                assert y.numpy().tobytes() == np.full(4, z * 1.0, np.float32).tobytes()
                if rep == 3:
                    assert reuse.hits == hits + 1
                    assert reuse.object_key([type(z)(z), y], (4,), stream) in reuse.known
    reuse = launch_plan(step, device, None).reuse
    plus = reuse.object_key([xs[0], g, 0.0, 0, xs[1]], (4,), None)
    assert plus is not None and plus != reuse.object_key([xs[0], g, -0.0, 0, xs[1]], (4,), None)
    assert plus == reuse.object_key([xs[0], g, 0, 0, xs[1]], (4,), None)  # an int 0 is +0.0
    # a NumPy scalar keys as the Python number of its value: the same key, the same value
    three = reuse.object_key([xs[0], g, 3.0, 5, xs[1]], (4,), None)
    assert three == reuse.object_key([xs[0], g, np.float32(3.0), np.int32(5), xs[1]], (4,), None)
    assert three != reuse.object_key([xs[0], g, np.float32(0.1), 5, xs[1]], (4,), None)
    assert reuse.object_key([xs[0], g, np.float32(0.1), 5, xs[1]], (4,), None) != (
        reuse.object_key([xs[0], g, 0.1, 5, xs[1]], (4,), None)
    )  # float32(0.1) is not 0.1: two keys (each converts to float32(0.1))
    for s in (np.float32(0.1), 0.1, np.float32(0.1), np.float32(np.nan), 0.1):
        for y in xs[1:]:
            for _ in range(3):
                wp.launch(step, 4, [xs[0], g, s, 0, y], device=device)
            np.testing.assert_array_equal(y.numpy(), np.float32(s))
    with pytest.raises(wp.KdslLaunchError, match=r"kernel 'step'.*argument 2 's'.*float64"):
        wp.launch(step, 4, [xs[0], g, np.float64(0.0), 0, xs[1]], device=device)
    with pytest.raises(wp.KdslLaunchError, match=r"kernel 'step'.*argument 3 'k'"):
        wp.launch(step, 4, [xs[0], g, 0.0, 0.0, xs[1]], device=device)
