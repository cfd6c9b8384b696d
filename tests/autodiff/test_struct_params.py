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
