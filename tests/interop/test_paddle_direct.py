"""Paddle tensors passed straight to ``launch`` and ``from_dlpack``, and the seed's Paddle
examples (Warp's interop guide, ``import kdsl as wp``); skipped without Paddle (issue 13)."""

import numpy as np
import pytest

import kdsl as wp

paddle = pytest.importorskip("paddle")
pytest.importorskip("paddle.utils.dlpack")

DEVICES = [
    "cpu",
    pytest.param("gpu:0", marks=pytest.mark.skipif(
        not (wp.is_cuda_available() and paddle.device.is_compiled_with_cuda()),
        reason="needs a GPU and Paddle built with CUDA")),
]  # fmt: skip


@wp.kernel
def _increment(a: wp.array(dtype=float)):
    i = wp.tid()
    a[i] = a[i] + 1.0


@wp.kernel
def loss(xs: wp.array(dtype=float, ndim=2), total: wp.array(dtype=float)):
    tid = wp.tid()
    wp.atomic_add(total, 0, xs[tid, 0] ** 2.0 + xs[tid, 1] ** 2.0)


@pytest.mark.parametrize("place", DEVICES)
def test_launch_takes_a_paddle_tensor(place):
    t = paddle.zeros([4], dtype="float32").to(place)
    wp.launch(_increment, 4, [t], device="cpu" if place == "cpu" else "cuda:0")
    wp.synchronize()
    np.testing.assert_array_equal(t.numpy(), np.ones(4))


@pytest.mark.parametrize("place", DEVICES)
def test_from_dlpack_takes_a_paddle_tensor_and_its_capsule(place):
    t = paddle.arange(4, dtype="float32").to(place)
    for source in (t, paddle.utils.dlpack.to_dlpack(t)):
        a = wp.from_dlpack(source)
        assert a.ptr == t.data_ptr()
        np.testing.assert_array_equal(a.numpy(), np.arange(4))


def test_seed_dlpack_round_trip():
    w = wp.array(np.arange(3, dtype=np.float32), dtype=float)
    t = paddle.utils.dlpack.from_dlpack(w)
    np.testing.assert_array_equal(t.numpy(), np.arange(3))
    w3 = wp.from_dlpack(paddle.utils.dlpack.to_dlpack(t))
    np.testing.assert_array_equal(w3.numpy(), np.arange(3))
    t2 = paddle.utils.dlpack.from_dlpack(wp.to_dlpack(w))
    assert t2.data_ptr() == w.ptr


def test_seed_optimization_with_from_paddle():
    paddle.seed(0)
    xs = paddle.randn([100, 2])
    xs.stop_gradient = False
    total = paddle.zeros([1])
    total.stop_gradient = False
    opt = paddle.optimizer.Adam(learning_rate=0.1, parameters=[xs])
    wp_xs, wp_l = wp.from_paddle(xs), wp.from_paddle(total)
    tape = wp.Tape()
    with tape:
        wp.launch(loss, dim=len(xs), inputs=[wp_xs], outputs=[wp_l], device=wp_xs.device)
    first = total.item()
    for _ in range(50):
        tape.zero()
        tape.backward(loss=wp_l)
        opt.step()
        wp_l.zero_()
        wp.launch(loss, dim=len(xs), inputs=[wp_xs], outputs=[wp_l], device=wp_xs.device)
    assert total.item() < 0.5 * first


def test_seed_optimization_with_to_paddle():
    rng = np.random.default_rng(0)
    xs = wp.array(rng.standard_normal((100, 2)), dtype=wp.float32, requires_grad=True)
    total = wp.zeros(1, dtype=wp.float32, requires_grad=True)
    opt = paddle.optimizer.Adam(learning_rate=0.1, parameters=[wp.to_paddle(xs)])
    tape = wp.Tape()
    with tape:
        wp.launch(loss, dim=len(xs), inputs=[xs], outputs=[total], device=xs.device)
    first = float(total.numpy()[0])
    for _ in range(50):
        tape.zero()
        tape.backward(loss=total)
        opt.step()
        total.zero_()
        wp.launch(loss, dim=len(xs), inputs=[xs], outputs=[total], device=xs.device)
    assert float(total.numpy()[0]) < 0.5 * first
