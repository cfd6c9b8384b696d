"""kdsl.autograd: jacobian, jacobian_fd, gradcheck, gradcheck_tape."""

import numpy as np
import pytest

import kdsl as wp
from kdsl.autograd import GradcheckError, gradcheck, gradcheck_tape, jacobian, jacobian_fd
from kdsl.errors import KdslError

F64 = wp.float64


@wp.kernel
def poly(x: wp.array(dtype=F64), s: F64, y: wp.array(dtype=F64), z: wp.array(dtype=F64)):
    i = wp.tid()
    y[i] = s * x[i] * x[i]
    z[i] = wp.sin(x[i]) + x[(i + 1) % 3]


@wp.kernel
def vec_norm(v: wp.array(dtype=wp.vec3d), out: wp.array(dtype=F64)):
    i = wp.tid()
    out[i] = wp.length(v[i])


@wp.kernel
def accumulate(x: wp.array(dtype=wp.float32), total: wp.array(dtype=wp.float32)):
    i = wp.tid()
    wp.atomic_add(total, 0, x[i] * x[i])


@wp.kernel
def wrong_grad(x: wp.array(dtype=F64), y: wp.array(dtype=F64)):
    # floor has a zero derivative almost everywhere, so AD says 0 but a coarse FD step sees
    # the jumps: a deliberate mismatch.
    i = wp.tid()
    y[i] = wp.floor(x[i] * 100.0)


@wp.kernel(enable_backward=False)
def no_backward(x: wp.array(dtype=F64), y: wp.array(dtype=F64)):
    i = wp.tid()
    y[i] = x[i]


X0 = np.array([0.3, -1.2, 2.0])


def arr(values, requires_grad=True, dtype=F64):
    return wp.array(np.asarray(values), dtype=dtype, requires_grad=requires_grad)


def poly_args():
    return [arr(X0), 1.5], [
        wp.zeros(3, dtype=F64, requires_grad=True),
        wp.zeros(3, dtype=F64, requires_grad=True),
    ]


def expected_poly():
    jy = np.diag(2 * 1.5 * X0)
    jz = np.diag(np.cos(X0)) + np.roll(np.eye(3), 1, axis=1)
    return jy, jz


def test_jacobians_of_a_kernel():
    inputs, outputs = poly_args()
    jy, jz = expected_poly()
    ad = jacobian(poly, 3, inputs, outputs)
    fd = jacobian_fd(poly, 3, inputs, outputs, eps=1e-6)
    assert set(ad) == set(fd) == {(0, 0), (0, 1)}  # the scalar s takes no part
    np.testing.assert_allclose(ad[0, 0], jy, rtol=1e-12)
    np.testing.assert_allclose(ad[0, 1], jz, rtol=1e-12)
    np.testing.assert_allclose(fd[0, 0], jy, atol=1e-8)
    np.testing.assert_allclose(fd[0, 1], jz, atol=1e-8)
    # Data and gradients are left as they were.
    np.testing.assert_array_equal(inputs[0].numpy(), X0)
    assert not np.any(outputs[0].numpy()) and not np.any(inputs[0].grad.numpy())


def test_masks_and_limits():
    inputs, outputs = poly_args()
    ad = jacobian(poly, 3, inputs, outputs, input_output_mask=[("x", "z")], max_outputs_per_var=2)
    assert set(ad) == {(0, 1)}
    assert np.isnan(ad[0, 1][2]).all() and not np.isnan(ad[0, 1][:2]).any()
    fd = jacobian_fd(poly, 3, inputs, outputs, input_output_mask=[(0, 0)], max_inputs_per_var=1)
    assert set(fd) == {(0, 0)} and np.isnan(fd[0, 0][:, 1:]).all()
    with pytest.raises(KdslError, match="no output 'w'"):
        jacobian(poly, 3, inputs, outputs, input_output_mask=[("x", "w")])


def test_vector_components_are_flattened():
    v0 = np.array([[1.0, 2.0, 2.0], [0.0, 3.0, 4.0]])
    v = wp.array(v0, dtype=wp.vec3d, requires_grad=True)
    out = wp.zeros(2, dtype=F64, requires_grad=True)
    ad = jacobian(vec_norm, 2, [v], [out])[0, 0]
    want = np.zeros((2, 6))
    want[0, :3], want[1, 3:] = v0[0] / 3.0, v0[1] / 5.0
    np.testing.assert_allclose(ad, want, rtol=1e-12)
    assert gradcheck(vec_norm, 2, [v], [out], eps=1e-6, atol=1e-7, rtol=1e-6, show_summary=False)


def test_gradcheck_passes_and_prints_a_summary(capsys):
    inputs, outputs = poly_args()
    assert gradcheck(poly, 3, inputs, outputs, eps=1e-6, atol=1e-7, rtol=1e-7)
    out = capsys.readouterr().out
    assert "Max Abs Error" in out and "PASS" in out and "passed" in out


def test_gradcheck_detects_a_wrong_gradient(capsys):
    x, y = arr([0.101, 0.2049, 0.3]), wp.zeros(3, dtype=F64, requires_grad=True)
    assert not gradcheck(wrong_grad, 3, [x], [y], eps=1e-2, raise_exception=False)
    assert "FAIL" in capsys.readouterr().out
    with pytest.raises(GradcheckError, match="x -> y: FAIL") as e:
        gradcheck(wrong_grad, 3, [x], [y], eps=1e-2, show_summary=False)
    assert isinstance(e.value, ValueError) and "float64" in str(e.value)


def test_float32_finite_differences_are_noisy():
    """Documented behaviour: float32 outputs limit FD precision; loosen eps/tolerances."""
    x0 = np.random.default_rng(0).normal(size=32)
    x = arr(x0, dtype=wp.float32)
    total = wp.zeros(1, dtype=wp.float32, requires_grad=True)
    ad = jacobian(accumulate, 32, [x], [total])[0, 0]
    np.testing.assert_allclose(ad[0], 2 * x0, rtol=1e-6)
    fd = jacobian_fd(accumulate, 32, [x], [total], eps=1e-5)[0, 0]
    assert np.abs(fd[0] - 2 * x0).max() > 1e-3  # float32 rounding / eps dominates
    assert gradcheck(
        accumulate, 32, [x], [total], eps=1e-2, atol=1e-2, rtol=1e-2, show_summary=False
    )


def test_python_function():
    def f(x, c):
        y = wp.zeros(3, dtype=F64, requires_grad=True)
        z = wp.zeros(3, dtype=F64, requires_grad=True)
        wp.launch(poly, 3, [x, c], [y, z])
        return [y, z]

    x = arr(X0)
    outer = wp.Tape()
    with outer:  # gradcheck's own launches stay off an active tape
        assert gradcheck(f, inputs=[x, 1.5], eps=1e-6, atol=1e-7, rtol=1e-7, show_summary=False)
    assert outer.launches == []
    ad = jacobian(f, inputs=[x, 1.5])
    np.testing.assert_allclose(ad[0, 1], expected_poly()[1], rtol=1e-12)


def test_python_function_inputs_are_restored():
    @wp.kernel
    def square_in_place(x: wp.array(dtype=F64)):
        i = wp.tid()
        x[i] = x[i] * x[i]

    def f(x):
        wp.launch(square_in_place, 3, [x], [])
        out = wp.zeros(3, dtype=F64, requires_grad=True)
        wp.copy(out, x)
        return out

    x = arr(X0)
    fd = jacobian_fd(f, inputs=[x], eps=1e-6)[0, 0]
    np.testing.assert_allclose(fd, np.diag(2 * X0), atol=1e-7)
    np.testing.assert_array_equal(x.numpy(), X0)


def test_gradcheck_tape():
    inputs, outputs = poly_args()
    total = wp.zeros(1, dtype=F64, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(poly, 3, inputs, outputs)
        wp.launch(no_backward, 3, [outputs[0]], [outputs[1]])  # skipped: no backward
        tape.record_func(lambda: None, [total])  # skipped: not a kernel
    assert gradcheck_tape(tape, eps=1e-6, atol=1e-7, rtol=1e-7, show_summary=False)
    assert gradcheck_tape(tape, whitelist_kernels=["no_backward"], show_summary=False)
    with pytest.raises(KdslError, match=r"takes a kdsl\.Tape"):
        gradcheck_tape([], show_summary=False)


def test_bad_arguments():
    inputs, outputs = poly_args()
    with pytest.raises(KdslError, match="dim is required"):
        jacobian(poly, None, inputs, outputs)
    with pytest.raises(KdslError, match="outputs"):
        jacobian(poly, 3, inputs, [])
    with pytest.raises(KdslError, match="takes 4 arguments"):
        jacobian(poly, 3, inputs[:1], outputs)
    with pytest.raises(KdslError, match="list of the function's arguments"):
        jacobian(poly, 3, inputs[0], outputs)
    with pytest.raises(KdslError, match="enable_backward=False"):
        jacobian(no_backward, 3, [arr(X0)], [wp.zeros(3, dtype=F64, requires_grad=True)])
    with pytest.raises(KdslError, match="requires_grad=True"):
        jacobian(poly, 3, [arr(X0, requires_grad=False), 1.0], outputs)
    with pytest.raises(KdslError, match="eps must be a positive"):
        jacobian_fd(poly, 3, inputs, outputs, eps=0)
    with pytest.raises(KdslError, match="kernel or a Python function"):
        gradcheck(42, 3, inputs, outputs)
    with pytest.raises(KdslError, match="must return a kdsl array"):
        jacobian(lambda x: x.numpy(), inputs=[arr(X0)])


def test_python_function_errors():
    def uses_no_backward(x):
        y = wp.zeros(3, dtype=F64, requires_grad=True)
        wp.launch(no_backward, 3, [x], [y])
        return y

    with pytest.raises(KdslError, match=r"no_backward.*enable_backward=False"):
        jacobian(uses_no_backward, inputs=[arr(X0)])

    def own_tape(x):
        with wp.Tape():
            return uses_no_backward(x)

    with pytest.raises(KdslError, match="opens its own Tape"):
        jacobian(own_tape, inputs=[arr(X0)])
