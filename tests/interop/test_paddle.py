"""Paddle: from_paddle/to_paddle zero-copy, grads and helpers (skipped without Paddle)."""

import pytest

import kdsl as wp
from kdsl.errors import KdslError

paddle = pytest.importorskip("paddle")


def test_from_paddle_is_zero_copy_with_vector_dtype():
    t = paddle.zeros([4, 3], dtype="float32")
    a = wp.from_paddle(t, dtype=wp.vec3)
    assert a.shape == (4,) and a.dtype is wp.vec3 and a.ptr == t.data_ptr()
    a.fill_(2.0)
    assert float(t.sum()) == 24.0


def test_to_paddle_is_zero_copy():
    a = wp.zeros(3, dtype=wp.vec3)
    t = wp.to_paddle(a)
    assert list(t.shape) == [3, 3] and t.data_ptr() == a.ptr
    a.fill_(1.0)
    assert float(t.sum()) == 9.0


def test_grads():
    t = paddle.ones([3], dtype="float32")
    t.stop_gradient = False
    a = wp.from_paddle(t)
    assert a.requires_grad and a.grad is not None and t.grad is not None
    b = wp.zeros(3, dtype=float, requires_grad=True)
    tb = wp.to_paddle(b)
    assert not tb.stop_gradient


def test_return_ctype_and_errors():
    d = wp.from_paddle(paddle.zeros([4], dtype="float32"), return_ctype=True)
    assert isinstance(d, wp.ArrayDescriptor) and d.shape == (4,)
    with pytest.raises(TypeError, match="no kdsl equivalent"):
        wp.from_paddle(paddle.zeros([2], dtype="bfloat16"))
    with pytest.raises(KdslError, match=r"takes a paddle\.Tensor"):
        wp.from_paddle([1.0])


def test_helpers():
    assert wp.device_from_paddle("cpu") == "cpu"
    assert wp.device_from_paddle(paddle.CPUPlace()) == "cpu"
    assert wp.device_to_paddle("cpu") == "cpu"
    assert wp.dtype_from_paddle(paddle.float32) is wp.float32
    assert wp.dtype_to_paddle(wp.float64) == paddle.float64
    assert wp.dtype_to_paddle(wp.uint32) == paddle.int32
    with pytest.raises(TypeError, match="no kdsl equivalent"):
        wp.dtype_from_paddle(paddle.complex64)
