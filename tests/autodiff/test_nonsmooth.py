"""Gradients at non-smooth points: one test per row of docs/autodiff.md's table.

Each row runs a float64 kernel under ``wp.Tape`` on interp, cpu and cuda, seeds the
output's adjoint with ones and checks the exact gradient of every operand at the kink,
the tie or the jump. Where warp-lang is installed, the same kernel (the same source,
built by the same factory with ``import warp``) runs under Warp's tape, and the
gradients must agree, except in the rows marked ``warp=...`` where kdsl keeps a
different, documented choice.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import kdsl as wp
from tests.device_targets import TARGETS

NAN = math.nan
#: The ``warp`` entry of a row whose builtin Warp 1.19 no longer has.
REMOVED = "removed in Warp 1.19"


# --- kernels, built for kdsl or for Warp by the same code -------------------------------


def _kernel(w, name):
    """``w.kernel``; for Warp, each kernel in a module of its own and named after its
    builtin: Warp's module hash does not see which builtin the closure's ``fn`` is."""
    return w.kernel if w is wp else w.kernel(module="unique", name=f"nonsmooth_{name}")


def unary(w, name):
    fn = getattr(w, name)

    @_kernel(w, f"unary_{name}")
    def k(x: w.array(dtype=w.float64), out: w.array(dtype=w.float64)):
        i = w.tid()
        out[i] = fn(x[i])

    return k


def binary(w, name):
    fn = getattr(w, name)

    @_kernel(w, f"binary_{name}")
    def k(a: w.array(dtype=w.float64), b: w.array(dtype=w.float64), out: w.array(dtype=w.float64)):
        i = w.tid()
        out[i] = fn(a[i], b[i])

    return k


def clamp(w, _name):
    @_kernel(w, f"clamp_{_name}")
    def k(
        x: w.array(dtype=w.float64), lo: w.array(dtype=w.float64),
        hi: w.array(dtype=w.float64), out: w.array(dtype=w.float64),
    ):  # fmt: skip
        i = w.tid()
        out[i] = w.clamp(x[i], lo[i], hi[i])

    return k


def reduce3(w, name):
    fn = getattr(w, name)

    @_kernel(w, f"reduce3_{name}")
    def k(v: w.array(dtype=w.vec3d), out: w.array(dtype=w.float64)):
        i = w.tid()
        out[i] = fn(v[i])

    return k


def select(w, _name):
    @_kernel(w, f"select_{_name}")
    def k(
        c: w.array(dtype=w.float64), a: w.array(dtype=w.float64),
        b: w.array(dtype=w.float64), out: w.array(dtype=w.float64),
    ):  # fmt: skip
        i = w.tid()
        out[i] = w.select(c[i] != 0.0, a[i], b[i])

    return k


def where(w, _name):
    @_kernel(w, f"where_{_name}")
    def k(
        c: w.array(dtype=w.float64), a: w.array(dtype=w.float64),
        b: w.array(dtype=w.float64), out: w.array(dtype=w.float64),
    ):  # fmt: skip
        i = w.tid()
        out[i] = w.where(c[i] != 0.0, a[i], b[i])

    return k


# --- the table: (row id, factory, builtin, operand values, expected gradients, warp) ------
# Operand values are one list per operand (one entry per thread); ``warp`` is None where
# Warp 1.19 gives the same gradients, else the gradients Warp gives (kdsl keeps its own;
# docs/autodiff.md says why).

ROWS = [
    ("abs at +0, -0 and off it", unary, "abs", [[0.0, -0.0, -2.0, 3.0]],
     [[1.0, 1.0, -1.0, 1.0]], None),
    ("sign", unary, "sign", [[0.0, -0.0, -2.0, 3.0]], [[0.0] * 4], None),
    ("min at a tie: to b", binary, "min", [[1.0, 0.0, -0.0, 1.0], [1.0, -0.0, 0.0, 2.0]],
     [[0.0, 0.0, 0.0, 1.0], [1.0, 1.0, 1.0, 0.0]], None),
    ("max at a tie: to b", binary, "max", [[1.0, 0.0, -0.0, 3.0], [1.0, -0.0, 0.0, 2.0]],
     [[0.0, 0.0, 0.0, 1.0], [1.0, 1.0, 1.0, 0.0]], None),
    ("min with one NaN: to the other", binary, "min", [[NAN, 2.0], [2.0, NAN]],
     [[0.0, 1.0], [1.0, 0.0]], None),
    ("max with one NaN: to the other", binary, "max", [[NAN, 2.0], [2.0, NAN]],
     [[0.0, 1.0], [1.0, 0.0]], None),
    ("min(v) at a tie: the first component", reduce3, "min", [[(1.0, 1.0, 2.0), (3.0, 2.0, 2.0)]],
     [[(1.0, 0.0, 0.0), (0.0, 1.0, 0.0)]], None),
    ("max(v) at a tie: the first component", reduce3, "max", [[(2.0, 2.0, 1.0), (1.0, 3.0, 3.0)]],
     [[(1.0, 0.0, 0.0), (0.0, 1.0, 0.0)]], None),
    ("clamp: inside, at lo, at hi, below, above, lo == hi", clamp, "clamp",
     [[0.5, 0.0, 1.0, -1.0, 2.0, 0.5], [0.0] * 5 + [0.5], [1.0] * 5 + [0.5]],
     [[1.0, 1.0, 0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0, 0.0, 0.0],
      [0.0, 0.0, 1.0, 0.0, 1.0, 1.0]], None),
    ("floor", unary, "floor", [[2.0, -2.0, 2.5]], [[0.0] * 3], None),
    ("ceil", unary, "ceil", [[2.0, -2.0, 2.5]], [[0.0] * 3], None),
    ("round", unary, "round", [[2.5, -2.5, 2.0]], [[0.0] * 3], None),
    ("rint", unary, "rint", [[2.5, -1.5, 2.0]], [[0.0] * 3], None),
    ("trunc", unary, "trunc", [[2.0, -2.0, 2.5]], [[0.0] * 3], None),
    ("step", unary, "step", [[0.0, -0.0, -1.0, 1.0]], [[0.0] * 4], None),
    ("nonzero", unary, "nonzero", [[0.0, 1.0]], [[0.0] * 2], None),
    ("select(cond, if_false, if_true)", select, "select",
     [[1.0, 0.0], [5.0, 5.0], [5.0, 5.0]], [[0.0, 0.0], [0.0, 1.0], [1.0, 0.0]], REMOVED),
    ("where(cond, a, b)", where, "where",
     [[1.0, 0.0], [5.0, 5.0], [5.0, 5.0]], [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], None),
    ("copysign at a = +0 and -0: by the sign bits", binary, "copysign",
     [[0.0, -0.0, 0.0, -0.0, -2.0], [2.0, 2.0, -2.0, -2.0, 3.0]],
     [[1.0, -1.0, -1.0, 1.0, -1.0], [0.0] * 5], None),
    # Warp's adj_frac is empty (its comment says the gradient is 1): kdsl gives 1.
    ("frac: 1 between integers", unary, "frac", [[0.25, -1.5, 2.0]], [[1.0] * 3],
     [[0.0] * 3]),
    # Warp's adj_mod gives b nothing; fmod(a, b) = a - trunc(a/b) b: kdsl gives -trunc(a/b).
    ("mod: -trunc(a/b) for b", binary, "mod", [[7.0, -7.0], [2.0, 2.0]],
     [[1.0, 1.0], [-3.0, 3.0]], [[1.0, 1.0], [0.0, 0.0]]),
]  # fmt: skip
IDS = [r[0] for r in ROWS]


def _arrays(w, factory, values, device):
    dtype = w.vec3d if factory is reduce3 else w.float64
    return [w.array(np.asarray(v, np.float64), dtype=dtype, device=device, requires_grad=True)
            for v in values]  # fmt: skip


def _gradients(w, factory, name, values, device, backend=None):
    kernel = factory(w, name)
    ins = _arrays(w, factory, values, device)
    n = len(values[0])
    out = w.zeros(n, dtype=w.float64, device=device, requires_grad=True)
    tape = w.Tape()
    with tape:
        if backend is None:
            w.launch(kernel, dim=n, inputs=ins, outputs=[out], device=device)
        else:
            w.launch(kernel, dim=n, inputs=ins, outputs=[out], device=device, backend=backend)
    out.grad.fill_(1.0)
    tape.backward()
    return [a.grad.numpy() for a in ins]


@pytest.mark.parametrize("device, backend", TARGETS)
@pytest.mark.parametrize("row", ROWS, ids=IDS)
def test_gradient_at_the_non_smooth_point(row, device, backend):
    _id, factory, name, values, expected, _warp = row
    got = _gradients(wp, factory, name, values, device, backend)
    for operand, (g, want) in enumerate(zip(got, expected)):
        assert np.all(np.isfinite(g)), f"operand {operand}: {g}"
        np.testing.assert_array_equal(g, np.asarray(want, np.float64), err_msg=f"operand {operand}")


@pytest.mark.parametrize("row", ROWS, ids=IDS)
def test_warp_gives_the_gradients_the_table_says(row):
    pytest.importorskip("warp")
    import warp

    warp.config.quiet = True
    _id, factory, name, values, expected, warp_expected = row
    if warp_expected == REMOVED:
        with pytest.raises(RuntimeError, match=rf"wp.{name}\(\) has been removed"):
            _gradients(warp, factory, name, values, "cpu")
        return
    got = _gradients(warp, factory, name, values, "cpu")
    for operand, (g, want) in enumerate(zip(got, warp_expected or expected)):
        np.testing.assert_array_equal(g, np.asarray(want, np.float64), err_msg=f"operand {operand}")
