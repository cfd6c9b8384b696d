"""Gradient conformance: the adjoint of every differentiable builtin and control-flow form.

Each case is a float64 kernel whose adjoint Jacobian must match central finite
differences (``kdsl.autograd.gradcheck``). Inputs stay away from the points where
a builtin is not differentiable (those have unit tests of their documented
subgradients in ``tests/autodiff``).
"""

from __future__ import annotations

import numpy as np

import kdsl as wp
from kdsl.testing.case import GradCase

F = wp.float64
V3 = wp.vec3d
M33 = wp.mat33d
N = 6

#: Unary math builtins and the interval their inputs are drawn from.
UNARY_DOMAINS = {
    "sqrt": (0.2, 2.0), "cbrt": (0.2, 2.0), "exp": (-1.5, 1.5), "exp2": (-1.5, 1.5),
    "log": (0.2, 2.0), "log2": (0.2, 2.0), "log10": (0.2, 2.0), "sin": (-2.0, 2.0),
    "cos": (-2.0, 2.0), "tan": (-1.2, 1.2), "asin": (-0.9, 0.9), "acos": (-0.9, 0.9),
    "atan": (-2.0, 2.0), "sinh": (-1.5, 1.5), "cosh": (-1.5, 1.5), "tanh": (-1.5, 1.5),
    "erf": (-1.5, 1.5), "erfc": (-1.5, 1.5), "abs": (0.2, 1.5), "floor": (0.1, 0.9),
    "ceil": (0.1, 0.9), "trunc": (0.1, 0.9), "round": (0.1, 0.4), "rint": (0.1, 0.4),
    "sign": (0.2, 1.0),
}  # fmt: skip


def _uniform(lo, hi, shape=(N,)):
    return lambda rng: rng.uniform(lo, hi, shape)


def _unary_case(name: str, lo: float, hi: float) -> GradCase:
    fn = getattr(wp, name)

    @wp.kernel
    def unary(x: wp.array(dtype=F), out: wp.array(dtype=F)):
        i = wp.tid()
        out[i] = fn(x[i] * F(1.0)) * x[i]

    def make(rng):
        # The inputs of sign/abs/... are negated half the time to see both sides.
        x = rng.uniform(lo, hi, N)
        if lo > 0 and name in ("abs", "sign", "floor", "ceil", "trunc", "round", "rint"):
            x[::2] *= -1
        return {"x": x, "out": np.zeros(N)}

    return GradCase(f"grad_{name}", unary, N, make, ("x",), ("out",))


@wp.kernel
def arith(a: wp.array(dtype=F), b: wp.array(dtype=F), out: wp.array(dtype=F)):
    i = wp.tid()
    x = a[i]
    y = b[i]
    out[i] = (x + y) * (x - y) / (y * y + F(1.0)) - (-x) + x % y


@wp.kernel
def binary_math(a: wp.array(dtype=F), b: wp.array(dtype=F), out: wp.array(dtype=F)):
    i = wp.tid()
    x = a[i]
    y = b[i]
    out[i] = wp.pow(x, y) + wp.atan2(y, x) + wp.copysign(x, y - F(1.0)) * y


@wp.kernel
def min_max_select(a: wp.array(dtype=F), b: wp.array(dtype=F), out: wp.array(dtype=F)):
    i = wp.tid()
    x = a[i]
    y = b[i]
    out[i] = wp.min(x, y) * F(2.0) + wp.max(x * y, y) + wp.select(x > y, x * x, y * x)


@wp.kernel
def vector_ops(p: wp.array(dtype=V3), q: wp.array(dtype=V3), out: wp.array(dtype=V3)):
    i = wp.tid()
    a = p[i]
    b = q[i]
    c = wp.cross(a, b)
    s = wp.dot(a, b) + wp.length(c) + wp.length_sq(a)
    out[i] = wp.normalize(c) * s + a * b[1] - b / (F(2.0) + a[0] * a[0])


@wp.kernel
def vector_components(p: wp.array(dtype=V3), out: wp.array(dtype=V3)):
    i = wp.tid()
    a = p[i]
    v = V3(a[2] * a[1], a[0], F(1.0))
    v[2] = a[0] * a[2]
    out[i] = v + V3(a[i % 3])


@wp.kernel
def matrix_ops(m: wp.array(dtype=M33), p: wp.array(dtype=V3), out: wp.array(dtype=V3)):
    i = wp.tid()
    a = m[i]
    v = p[i]
    b = a * wp.transpose(a) + wp.outer(v, v)
    r = b * v + v * a
    out[i] = r + a[1] * b[2, 0]


@wp.kernel
def scalar_library(a: wp.array(dtype=F), b: wp.array(dtype=F), out: wp.array(dtype=F)):
    # Library (stdlib) builtins are differentiated through their kdsl code.
    i = wp.tid()
    x = a[i]
    y = b[i]
    out[i] = (wp.lerp(x, y, F(0.3)) + wp.smoothstep(F(0.0), F(2.0), x)
              + wp.clamp(x * y, F(-0.5), F(0.8)) + wp.erfinv(x * F(0.5)))  # fmt: skip


@wp.kernel
def matrix_library(m: wp.array(dtype=M33), p: wp.array(dtype=V3), out: wp.array(dtype=V3)):
    i = wp.tid()
    a = m[i] + wp.identity(n=3, dtype=F) * F(3.0)  # well conditioned
    v = p[i]
    w = wp.inverse(a) * v * wp.determinant(a) + wp.cw_mul(v, wp.get_diag(a))
    out[i] = w + V3(F(1.0), F(2.0), F(3.0)) * (wp.trace(a) * wp.norm_l2(v))


@wp.kernel
def geometry_library(q: wp.array(dtype=wp.quatd), p: wp.array(dtype=V3), out: wp.array(dtype=V3)):
    i = wp.tid()
    r = wp.normalize(q[i])
    t = wp.transformation(p[i], r)
    out[i] = (wp.quat_rotate(r, p[i]) + wp.transform_point(t, p[i] * F(2.0))
              + wp.quat_rotate_inv(r * r, p[i]))  # fmt: skip


@wp.kernel
def spatial_library(a: wp.array(dtype=wp.spatial_vectord), b: wp.array(dtype=wp.spatial_vectord),
                    out: wp.array(dtype=wp.spatial_vectord)):  # fmt: skip
    i = wp.tid()
    x = a[i]
    y = b[i]
    out[i] = wp.spatial_cross(x, y) + wp.spatial_cross_dual(y, x) * wp.spatial_dot(x, y)


# -- control flow ----------------------------------------------------------------


@wp.kernel
def branch(x: wp.array(dtype=F), out: wp.array(dtype=F)):
    i = wp.tid()
    v = x[i]
    r = F(0.0)
    if v > F(0.0):
        r = v * v * F(3.0)
    else:
        r = wp.sin(v)
    out[i] = r * v


@wp.kernel
def static_loop(x: wp.array(dtype=F), out: wp.array(dtype=F)):
    i = wp.tid()
    v = x[i]
    s = F(0.0)
    for _ in range(5):
        s = s * v + wp.cos(s)
    out[i] = s


@wp.kernel
def dynamic_loop(x: wp.array(dtype=F), n: int, out: wp.array(dtype=F)):
    i = wp.tid()
    v = x[i]
    s = F(0.5)
    for _ in range(n):
        s = wp.sin(s * v) + s
    out[i] = s


@wp.kernel
def while_loop(x: wp.array(dtype=F), out: wp.array(dtype=F)):
    # The trip count depends on the data and differs between threads.
    i = wp.tid()
    v = x[i]
    s = F(1.0)
    while s < F(20.0):
        s = s * v + F(0.5)
    out[i] = s * v


@wp.kernel
def break_continue(x: wp.array(dtype=F), n: int, out: wp.array(dtype=F)):
    i = wp.tid()
    v = x[i]
    s = F(0.0)
    for j in range(n):
        if j % 3 == 1:
            continue
        s = s + wp.sin(v * F(j)) * v
        if s > F(2.0):
            break
    out[i] = s


@wp.kernel
def nested_loops(x: wp.array(dtype=F), n: int, out: wp.array(dtype=F)):
    i = wp.tid()
    v = x[i]
    s = F(0.1)
    for j in range(n):
        t = s
        for _ in range(j):
            t = t * F(0.9) + v * F(0.01)
        s = s + wp.tanh(t)
    out[i] = s


@wp.kernel
def gather_in_loop(x: wp.array(dtype=F), n: int, out: wp.array(dtype=F)):
    # Each thread reads many elements: the adjoint scatters with atomics.
    i = wp.tid()
    s = F(0.0)
    for j in range(n):
        s = s + x[(i + j) % n] * F(j + 1) * s + x[j]
    out[i] = s


@wp.kernel
def loop_in_branch(x: wp.array(dtype=F), n: int, out: wp.array(dtype=F)):
    i = wp.tid()
    v = x[i]
    r = v
    if v > F(0.3):
        for _ in range(n):
            r = r * F(0.5) + wp.sqrt(r * r + F(1.0))
    out[i] = r


@wp.kernel
def spring(x0: wp.array(dtype=V3), k: wp.array(dtype=F), steps: int, out: wp.array(dtype=V3)):
    # Semi-implicit Euler of a damped spring, carrying vector state.
    i = wp.tid()
    x = x0[i]
    v = V3(F(0.0), F(0.0), F(0.0))
    stiff = k[0]
    for _ in range(steps):
        f = -stiff * x - F(0.1) * v
        v = v + f * F(0.01)
        x = x + v * F(0.01)
    out[i] = x


@wp.kernel
def atomic_loss(x: wp.array(dtype=F), loss: wp.array(dtype=F)):
    i = wp.tid()
    wp.atomic_add(loss, 0, x[i] * x[i] * F(0.5))


@wp.kernel
def two_d(x: wp.array2d(dtype=F), out: wp.array2d(dtype=F)):
    i, j = wp.tid()
    out[i, j] = x[i, j] * x[j, i] + wp.cos(x[i, j])


def _xs(*names, lo=0.2, hi=1.2, shape=(N,), extra=None):
    def make(rng):
        d = {n: rng.uniform(lo, hi, shape) for n in names}
        d.update(extra or {})
        return d

    return make


def _vecs(*names, extra=None, n=4):
    def make(rng):
        d = {name: rng.uniform(-1.0, 1.0, (n, 3)) for name in names}
        d.update(extra or {})
        return d

    return make


CASES = [
    *(_unary_case(name, lo, hi) for name, (lo, hi) in UNARY_DOMAINS.items()),
    GradCase("grad_arith", arith, N, _xs("a", "b", extra={"out": np.zeros(N)}), ("a", "b"),
             ("out",)),
    GradCase("grad_binary_math", binary_math, N,
             _xs("a", "b", lo=0.3, hi=1.5, extra={"out": np.zeros(N)}), ("a", "b"), ("out",)),
    GradCase("grad_min_max_select", min_max_select, N,
             _xs("a", "b", lo=-1.0, hi=1.0, extra={"out": np.zeros(N)}), ("a", "b"), ("out",)),
    GradCase("grad_vector_ops", vector_ops, 4, _vecs("p", "q", extra={"out": np.zeros((4, 3))}),
             ("p", "q"), ("out",)),
    GradCase("grad_vector_components", vector_components, 4,
             _vecs("p", extra={"out": np.zeros((4, 3))}), ("p",), ("out",)),
    GradCase("grad_matrix_ops", matrix_ops, 3,
             lambda rng: {"m": rng.uniform(-1, 1, (3, 3, 3)), "p": rng.uniform(-1, 1, (3, 3)),
                          "out": np.zeros((3, 3))}, ("m", "p"), ("out",)),
    GradCase("grad_scalar_library", scalar_library, N,
             _xs("a", "b", lo=-0.9, hi=0.9, extra={"out": np.zeros(N)}), ("a", "b"), ("out",)),
    GradCase("grad_matrix_library", matrix_library, 3,
             lambda rng: {"m": rng.uniform(-1, 1, (3, 3, 3)), "p": rng.uniform(-1, 1, (3, 3)),
                          "out": np.zeros((3, 3))}, ("m", "p"), ("out",)),
    GradCase("grad_geometry_library", geometry_library, 4,
             lambda rng: {"q": rng.uniform(-1, 1, (4, 4)), "p": rng.uniform(-1, 1, (4, 3)),
                          "out": np.zeros((4, 3))}, ("q", "p"), ("out",)),
    GradCase("grad_spatial_library", spatial_library, 4,
             lambda rng: {"a": rng.uniform(-1, 1, (4, 6)), "b": rng.uniform(-1, 1, (4, 6)),
                          "out": np.zeros((4, 6))}, ("a", "b"), ("out",)),
    GradCase("grad_branch", branch, N, _xs("x", lo=-1.0, hi=1.0, extra={"out": np.zeros(N)}),
             ("x",), ("out",)),
    GradCase("grad_static_loop", static_loop, N, _xs("x", extra={"out": np.zeros(N)}), ("x",),
             ("out",)),
    GradCase("grad_dynamic_loop", dynamic_loop, N, _xs("x", extra={"n": 7, "out": np.zeros(N)}),
             ("x",), ("out",)),
    GradCase("grad_while_loop", while_loop, N,
             _xs("x", lo=1.3, hi=2.0, extra={"out": np.zeros(N)}), ("x",), ("out",)),
    GradCase("grad_break_continue", break_continue, N,
             _xs("x", extra={"n": 12, "out": np.zeros(N)}), ("x",), ("out",)),
    GradCase("grad_nested_loops", nested_loops, 4,
             _xs("x", shape=(4,), extra={"n": 5, "out": np.zeros(4)}), ("x",), ("out",)),
    GradCase("grad_gather_in_loop", gather_in_loop, 5,
             _xs("x", lo=-0.3, hi=0.3, shape=(5,), extra={"n": 5, "out": np.zeros(5)}), ("x",),
             ("out",)),
    GradCase("grad_loop_in_branch", loop_in_branch, N,
             _xs("x", lo=0.0, hi=1.0, extra={"n": 4, "out": np.zeros(N)}), ("x",), ("out",)),
    GradCase("grad_spring", spring, 3,
             _vecs("x0", n=3, extra={"k": np.array([40.0]), "steps": 50, "out": np.zeros((3, 3))}),
             ("x0", "k"), ("out",)),
    GradCase("grad_atomic_loss", atomic_loss, N, _xs("x", extra={"loss": np.zeros(1)}), ("x",),
             ("loss",)),
    GradCase("grad_two_d", two_d, (3, 3), _xs("x", lo=-1.0, hi=1.0, shape=(3, 3),
                                              extra={"out": np.zeros((3, 3))}), ("x",), ("out",)),
]  # fmt: skip


@wp.struct
class GradState:
    s: F
    v: V3


@wp.kernel
def struct_values(a: wp.array(dtype=F), p: wp.array(dtype=V3), out: wp.array(dtype=V3)):
    i = wp.tid()
    st = GradState(s=a[i], v=p[i])
    st.s = st.s * st.s + F(0.5)
    st.v = st.v * st.s
    st.v.y = st.v.y + wp.sin(st.s)
    out[i] = st.v * a[i] + GradState().v


# Gradients through struct values (construct, field reads, field updates).
CASES.append(
    GradCase("grad_struct_values", struct_values, 4,
             lambda rng: {"a": rng.uniform(0.2, 1.2, 4), "p": rng.uniform(-1, 1, (4, 3)),
                          "out": np.zeros((4, 3))}, ("a", "p"), ("out",))
)  # fmt: skip
