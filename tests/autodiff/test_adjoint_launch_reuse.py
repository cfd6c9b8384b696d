"""Adjoint launches: the per-kernel plan, scratch gradients and packed-launch reuse.

A backward pass replays many adjoint launches; ``launch_adjoint`` keeps per kernel
what does not change between them (``_AdjointPlan``), keeps the scratch gradients
of arrays without one (cleared before every launch) and reuses the packed launch
of unchanged arguments (``LaunchReuse``). These tests check that none of it changes
a gradient, however often or in whatever order the launches repeat.
"""

import numpy as np
import pytest

import kdsl as wp
from kdsl.runtime.adjoint import adjoint_kernel
from kdsl.runtime.launch import launch_plan
from tests.device_targets import TARGETS


@wp.kernel
def through_scratch(x: wp.array(dtype=float), tmp: wp.array(dtype=float),
                    y: wp.array(dtype=float)):  # fmt: skip
    # tmp has no gradient: its adjoint is scratch memory, read back by the adjoint.
    i = wp.tid()
    tmp[i] = x[i] * 2.0
    y[i] = tmp[i] * 3.0


@wp.kernel
def flight_step(x: wp.array(dtype=float), h: float, x1: wp.array(dtype=float)):
    i = wp.tid()
    x1[i] = x[i] + h * x[i] * x[i]


@wp.kernel
def total(x: wp.array(dtype=float), loss: wp.array(dtype=float)):
    wp.atomic_add(loss, 0, x[wp.tid()])


@pytest.mark.filterwarnings("ignore:kernel reads array 'tmp' after writing it")
@pytest.mark.parametrize(("dev", "backend"), TARGETS)
def test_scratch_gradients_start_from_zero_at_every_launch(dev, backend):
    x = wp.array(np.arange(4, dtype=np.float32), device=dev, requires_grad=True)
    tmp = wp.zeros(4, dtype=float, device=dev)  # no gradient
    y = wp.zeros(4, dtype=float, device=dev, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(through_scratch, 4, [x, tmp, y], device=dev, backend=backend)
    for _ in range(3):  # a scratch gradient left over would add into the next pass
        tape.backward(grads={y: wp.ones(4, dtype=float, device=dev)})
        np.testing.assert_array_equal(x.grad.numpy(), np.full(4, 6.0, np.float32))
        tape.zero()


def _flight(xs, loss, h, dev, backend):
    tape = wp.Tape()
    with tape:
        for k in range(len(xs) - 1):
            wp.launch(flight_step, len(xs[0]), [xs[k], h, xs[k + 1]], device=dev, backend=backend)
        wp.launch(total, len(xs[0]), [xs[-1], loss], device=dev, backend=backend)
    tape.backward(loss=loss)
    return tape


@pytest.mark.parametrize(("dev", "backend"), TARGETS)
def test_repeated_taped_flights_give_the_same_gradient(dev, backend):
    # More steps than a small reuse table holds: every adjoint launch repeats only after
    # the others, as in a simulation optimized through its tape.
    steps, h = 40, 0.01
    x0 = np.linspace(0.1, 0.5, 8).astype(np.float32)
    xs = [wp.zeros(8, dtype=float, device=dev, requires_grad=True) for _ in range(steps + 1)]
    loss = wp.zeros(1, dtype=float, device=dev, requires_grad=True)
    grads = []
    for _ in range(3):
        xs[0].assign(x0)
        loss.zero_()
        tape = _flight(xs, loss, h, dev, backend)
        grads.append(xs[0].grad.numpy().copy())
        tape.zero()
    expect = np.ones(8)
    x = x0.astype(np.float64)
    path = []
    for _ in range(steps):
        path.append(x)
        x = x + h * x * x
    for xk in reversed(path):
        expect = expect * (1.0 + 2.0 * h * xk)
    for g in grads:
        np.testing.assert_allclose(g, expect, rtol=1e-5)
    assert np.array_equal(grads[0], grads[1]) and np.array_equal(grads[1], grads[2])
    if dev == "cpu" and backend is None:  # later passes reused the adjoints' packing
        plan = launch_plan(adjoint_kernel(flight_step), dev, backend)
        assert plan.reuse.hits >= steps


@pytest.mark.parametrize("backend", ["interp", "cpu"])
def test_a_changed_scalar_argument_is_not_replayed_from_the_reuse(backend):
    x = wp.array(np.full(4, 2.0, np.float32), requires_grad=True)
    x1 = wp.zeros(4, dtype=float, requires_grad=True)
    for h in (0.5, 0.5, 0.25, 0.25, 1.0):
        tape = wp.Tape()
        with tape:
            wp.launch(flight_step, 4, [x, h, x1], backend=backend)
        tape.backward(grads={x1: wp.ones(4, dtype=float)})
        np.testing.assert_array_equal(x.grad.numpy(), np.full(4, 1.0 + 4.0 * h, np.float32))
        tape.zero()


def test_adjoint_launch_grid_is_checked():
    x = wp.zeros(4, dtype=float, requires_grad=True)
    x1 = wp.zeros(4, dtype=float, requires_grad=True)
    for bad in ((4, -1), (1.5,), (True,), ()):
        with pytest.raises(wp.KdslError, match="dim must"):
            wp.launch(flight_step, bad, [x, 0.1], [x1], adj_inputs=[x.grad, None],
                      adj_outputs=[x1.grad], adjoint=True)  # fmt: skip


@pytest.mark.filterwarnings("ignore:kernel reads array 'tmp' after writing it")
@pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")
def test_scratch_gradients_on_another_stream_cuda():
    """Launches on a stream other than the device's current one get fresh scratch (the
    kept one is cleared on the current stream, which would not order with theirs)."""
    dev = "cuda:0"
    stream = wp.Stream(dev)
    x = wp.array(np.arange(4, dtype=np.float32), device=dev, requires_grad=True)
    tmp = wp.zeros(4, dtype=float, device=dev)
    y = wp.zeros(4, dtype=float, device=dev, requires_grad=True)
    for s in (stream, None, stream, None):
        tape = wp.Tape()
        with tape:
            wp.launch(through_scratch, 4, [x, tmp, y], device=dev, stream=s)
        tape.backward(grads={y: wp.ones(4, dtype=float, device=dev)})
        wp.synchronize_device(dev)
        np.testing.assert_array_equal(x.grad.numpy(), np.full(4, 6.0, np.float32))
        tape.zero()


def test_backward_orders_side_streams_with_the_current_one(monkeypatch):
    """Adjoints replay on their launch's stream; ``backward`` makes that stream wait for
    the current one (the seeded gradients, ``zero()``) before, and the current stream
    wait for it after. Stand-in streams: no GPU needed."""
    from kdsl.runtime import tape as tape_mod

    log = []

    class FakeStream:
        def __init__(self, name, handle):
            self.name, self.cuda_stream, self.device = name, handle, "gpu"

        def wait_stream(self, other):
            log.append(f"{self.name} waits for {other.name}")

    current, side = FakeStream("current", 1), FakeStream("side", 2)
    same_handle = FakeStream("alias", 1)  # another object over the current stream
    monkeypatch.setattr(tape_mod, "current_stream", lambda device: current)
    records = [tape_mod.LaunchRecord(None, 1, 0, [], [], None, 256, {}, None, s)
               for s in (None, current, side, same_handle, side)]  # fmt: skip
    assert tape_mod._side_streams(records) == [(side, current)]
    tape = wp.Tape()
    tape.launches.extend(records[:1])  # a cpu launch (no stream): nothing to order
    tape.launches.append(lambda: log.append("replay"))
    tape.backward()
    assert log == ["replay"]
    log.clear()
    tape.launches.append(records[2])
    monkeypatch.setattr(tape, "_replay", lambda rec: log.append(f"replay on {rec.stream and rec.stream.name}"))
    tape.backward()
    assert log == ["side waits for current", "replay on side", "replay", "replay on None",
                   "current waits for side"]  # fmt: skip
