"""Gradients through kernels that read several fields of a ``@kdsl.struct`` argument.

The "simulation parameters" pattern (``y[i] = x[i] * p.a + p.b``): each field read
adds a struct-typed contribution to the struct's adjoint, and those contributions
must add field by field (issue 13).
"""

import re
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import kdsl as wp


@wp.struct
class Inner:
    c: float


@wp.struct
class Params:
    a: float
    b: float
    n: int
    inner: Inner


@wp.kernel
def affine(x: wp.array(dtype=float), p: Params, y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = x[i] * p.a + p.b


@wp.kernel
def affine_loop(x: wp.array(dtype=float), p: Params, y: wp.array(dtype=float)):
    i = wp.tid()
    s = 0.0
    for _ in range(p.n):  # a dynamic loop reading the fields each iteration
        s = s + x[i] * x[i] * p.a + p.b * p.inner.c
    y[i] = s * p.inner.c


def _params(a=2.0, b=3.0, n=3, c=0.5):
    p = Params()
    p.a, p.b, p.n = a, b, n
    p.inner = Inner()
    p.inner.c = c
    return p


X0 = np.array([0.0, 1.0, -2.0, 0.5], dtype=np.float32)


def _x_grad(kernel, p, backend):
    x = wp.array(X0, dtype=float, requires_grad=True)
    y = wp.zeros(4, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(kernel, 4, [x, p], [y], backend=backend)
    tape.backward(grads={y: wp.ones(4, dtype=float)})
    return y.numpy(), x.grad.numpy()


@pytest.mark.parametrize("backend", ["interp", "cpu"])
def test_struct_with_two_fields_read_differentiates(backend):
    y, gx = _x_grad(affine, _params(), backend)
    np.testing.assert_allclose(y, X0 * 2.0 + 3.0)
    np.testing.assert_allclose(gx, np.full(4, 2.0))


@pytest.mark.parametrize("backend", ["interp", "cpu"])
def test_struct_fields_and_nested_struct_in_dynamic_loop_differentiate(backend):
    y, gx = _x_grad(affine_loop, _params(), backend)
    np.testing.assert_allclose(y, 3 * (X0 * X0 * 2.0 + 1.5) * 0.5, rtol=1e-6)
    np.testing.assert_allclose(gx, 3 * 4.0 * X0 * 0.5, rtol=1e-6)


def test_kdsl_ir_adjoint_stage_of_struct_kernel(tmp_path):
    src = tmp_path / "params.py"
    src.write_text(
        textwrap.dedent("""
        import kdsl as wp

        @wp.struct
        class Params:
            a: float
            b: float

        @wp.kernel
        def k(x: wp.array(dtype=float), p: Params, y: wp.array(dtype=float)):
            i = wp.tid()
            y[i] = x[i] * p.a + p.b
    """)
    )
    proc = subprocess.run([sys.executable, "-m", "kdsl", "ir", "--stage", "adjoint", f"{src}:k"],
                          capture_output=True, text=True, timeout=120)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert re.search(r"func.func @k_\w*__adj\(", proc.stdout), proc.stdout
    assert "internal error" not in proc.stderr


@wp.struct
class Weights:
    w: wp.array(dtype=float)
    scale: float


@wp.struct
class Model:
    weights: Weights
    bias: wp.array(dtype=float)


@wp.kernel
def weighted_sum(m: Model, x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    acc = 0.0
    for j in range(m.weights.w.shape[0]):  # a dynamic loop over a struct's array
        acc += m.weights.w[j] * x[i]
    y[i] = acc * m.weights.scale + m.bias[i]


@pytest.mark.parametrize("backend", ["interp", "cpu"])
def test_gradients_reach_arrays_held_in_struct_fields(backend):
    w = wp.array([1.0, 2.0, 3.0], dtype=float, requires_grad=True)
    bias = wp.array([0.5, -0.5], dtype=float, requires_grad=True)
    x = wp.array([1.0, 2.0], dtype=float, requires_grad=True)
    y = wp.zeros(2, dtype=float, requires_grad=True)
    m = Model()
    m.weights = Weights()
    m.weights.w, m.weights.scale, m.bias = w, 2.0, bias
    tape = wp.Tape()
    with tape:
        wp.launch(weighted_sum, dim=2, inputs=[m, x], outputs=[y], backend=backend)
    tape.backward(grads={y: wp.array([1.0, 10.0], dtype=float)})
    # dy_i/dw_j = x_i * scale, dy_i/dbias_i = 1, dy_i/dx_i = scale * sum(w)
    np.testing.assert_allclose(w.grad.numpy(), [2.0 * (1.0 + 20.0)] * 3)
    np.testing.assert_allclose(bias.grad.numpy(), [1.0, 10.0])
    np.testing.assert_allclose(x.grad.numpy(), [12.0, 120.0])
    np.testing.assert_allclose(w.numpy(), [1.0, 2.0, 3.0])  # the inputs are untouched


def test_struct_array_without_grad_gets_scratch_and_leaves_input_alone():
    w = wp.array([1.0, 2.0, 3.0], dtype=float)  # no requires_grad
    bias = wp.array([0.0, 0.0], dtype=float, requires_grad=True)
    x = wp.array([1.0, 2.0], dtype=float, requires_grad=True)
    y = wp.zeros(2, dtype=float, requires_grad=True)
    m = Model()
    m.weights = Weights()
    m.weights.w, m.weights.scale, m.bias = w, 1.0, bias
    tape = wp.Tape()
    with tape:
        wp.launch(weighted_sum, dim=2, inputs=[m, x], outputs=[y])
    tape.backward(grads={y: wp.array([1.0, 1.0], dtype=float)})
    np.testing.assert_allclose(w.numpy(), [1.0, 2.0, 3.0])
    np.testing.assert_allclose(x.grad.numpy(), [6.0, 6.0])
