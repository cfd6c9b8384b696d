"""Property test: random expressions over the builtins, every backend against NumPy float64.

Hypothesis draws expression trees over the math builtins (each operand kept inside
its function's domain by construction), writes them as a float64 kernel into a
module file, and compares each backend's results with the same expression
evaluated by NumPy in float64. Runs on interp and cpu here (and cuda on a GPU).
"""

from __future__ import annotations

import importlib.util
import itertools
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import kdsl
from kdsl.testing.conformance import targets

N = 16

#: name -> (kernel source template, NumPy function). ``{0}``/``{1}`` are operands.
UNARY = {
    "sin": ("wp.sin({0})", np.sin),
    "cos": ("wp.cos({0})", np.cos),
    "tanh": ("wp.tanh({0})", np.tanh),
    "atan": ("wp.atan({0})", np.arctan),
    "abs": ("wp.abs({0})", np.abs),
    "neg": ("(-{0})", np.negative),
    "sqrt": ("wp.sqrt(wp.abs({0}) + F(0.25))", lambda a: np.sqrt(np.abs(a) + 0.25)),
    "log": ("wp.log(wp.abs({0}) + F(0.5))", lambda a: np.log(np.abs(a) + 0.5)),
    "exp": ("wp.exp(wp.clamp({0}, F(-4.0), F(4.0)))", lambda a: np.exp(np.clip(a, -4, 4))),
    "erf": ("wp.erf({0})", None),  # NumPy has no erf: see _erf
    "cbrt": ("wp.cbrt({0})", np.cbrt),
    "asin": ("wp.asin(wp.tanh({0}) * F(0.9))", lambda a: np.arcsin(np.tanh(a) * 0.9)),
    "smoothstep": ("wp.smoothstep(F(-1.0), F(1.0), {0})",
                   lambda a: (lambda t: t * t * (3 - 2 * t))(np.clip((a + 1) / 2, 0, 1))),
}  # fmt: skip
BINARY = {
    "add": ("({0} + {1})", np.add),
    "sub": ("({0} - {1})", np.subtract),
    "mul": ("({0} * {1})", np.multiply),
    "div": ("({0} / (wp.abs({1}) + F(0.5)))", lambda a, b: a / (np.abs(b) + 0.5)),
    "min": ("wp.min({0}, {1})", np.minimum),
    "max": ("wp.max({0}, {1})", np.maximum),
    "atan2": ("wp.atan2({0}, {1})", np.arctan2),
    "pow": ("wp.pow(wp.abs({0}) + F(0.5), wp.clamp({1}, F(-2.0), F(2.0)))",
            lambda a, b: np.power(np.abs(a) + 0.5, np.clip(b, -2, 2))),
    "lerp": ("wp.lerp({0}, {1}, F(0.25))", lambda a, b: a + 0.25 * (b - a)),
    "clamp": ("wp.clamp({0}, F(-1.0), {1})", lambda a, b: np.minimum(np.maximum(a, -1.0), b)),
}  # fmt: skip


def _erf(a):
    from math import erf

    return np.vectorize(erf)(a)


def expressions(depth: int):
    """Strategy of (source, numpy evaluator) pairs over the leaves x and y."""
    leaves = st.sampled_from([("x", lambda x, y: x), ("y", lambda x, y: y),
                              ("F(0.75)", lambda x, y: np.full_like(x, 0.75))])  # fmt: skip
    if depth == 0:
        return leaves

    sub = expressions(depth - 1)

    def unary(pair):
        name, (src, _) = pair[0], UNARY[pair[0]]
        fn = UNARY[name][1] or _erf
        s, f = pair[1]
        return src.format(s), lambda x, y: fn(f(x, y))

    def binary(t):
        name, (a, fa), (b, fb) = t
        src, fn = BINARY[name]
        return src.format(a, b), lambda x, y: fn(fa(x, y), fb(x, y))

    return st.one_of(
        leaves,
        st.tuples(st.sampled_from(sorted(UNARY)), sub).map(unary),
        st.tuples(st.sampled_from(sorted(BINARY)), sub, sub).map(binary),
    )


_counter = itertools.count()


def _kernel(tmp: Path, source: str):
    """A float64 kernel computing ``out[i] = <source>`` from x[i] and y[i]."""
    name = f"expr_{next(_counter)}"
    path = tmp / f"{name}.py"
    path.write_text(
        "import kdsl as wp\nF = wp.float64\n\n\n@wp.kernel\n"
        "def k(xs: wp.array(dtype=F), ys: wp.array(dtype=F), out: wp.array(dtype=F)):\n"
        "    i = wp.tid()\n    x = xs[i]\n    y = ys[i]\n"
        f"    out[i] = {source}\n"
    )
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.k


BACKENDS = [t for t in targets() if t.backend in ("interp", "cpu", "cuda")]


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    return tmp_path_factory.mktemp("exprs")


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(expr=expressions(4), seed=st.integers(0, 2**16))
def test_random_expressions_match_float64(workdir, expr, seed):
    source, reference = expr
    rng = np.random.default_rng(seed)
    x = rng.uniform(-2.0, 2.0, N)
    y = rng.uniform(-2.0, 2.0, N)
    with np.errstate(all="ignore"):
        want = reference(x, y) * np.ones(N)
    kernel = _kernel(workdir, source)
    for target in BACKENDS:
        xs = kdsl.array(x, dtype=kdsl.float64, device=target.device)
        ys = kdsl.array(y, dtype=kdsl.float64, device=target.device)
        out = kdsl.zeros(N, dtype=kdsl.float64, device=target.device)
        kdsl.launch(kernel, N, [xs, ys, out], device=target.device, backend=target.backend)
        np.testing.assert_allclose(out.numpy(), want, rtol=1e-9, atol=1e-12,
                                   err_msg=f"{target}: out = {source}")  # fmt: skip
