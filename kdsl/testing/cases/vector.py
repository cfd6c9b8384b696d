"""Vectors and matrices: construction, components, dot/cross/length/normalize, matmul."""

import numpy as np

import kdsl as wp
from kdsl.testing.case import Case, f64, uniform

N = 32


def _vecs(rng, n=N, lo=-3.0, hi=3.0):
    return uniform(rng, (n, 3), lo, hi)


@wp.kernel
def vec_construct(
    a: wp.array(dtype=float),
    b: wp.array(dtype=float),
    c: wp.array(dtype=float),
    out: wp.array(dtype=wp.vec3),
    splat: wp.array(dtype=wp.vec3),
):
    i = wp.tid()
    out[i] = wp.vec3(a[i], b[i], c[i])
    splat[i] = wp.vec3(a[i])


@wp.kernel
def vec_components(
    v: wp.array(dtype=wp.vec3), out: wp.array(dtype=float), attrs: wp.array(dtype=float)
):
    i = wp.tid()
    x = v[i]
    out[i] = x[0] + 2.0 * x[1] + 3.0 * x[2]
    attrs[i] = x.x - x.y * x.z


@wp.kernel
def vec_assign(v: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    x = v[i]
    x[1] = 5.0
    x[0] += x[2]
    out[i] = x


@wp.kernel
def vec_arith(
    a: wp.array(dtype=wp.vec3),
    b: wp.array(dtype=wp.vec3),
    s: wp.array(dtype=float),
    out: wp.array(dtype=wp.vec3),
):
    i = wp.tid()
    out[i] = (a[i] + b[i]) * s[i] - a[i] / 2.0 + -b[i]


@wp.kernel
def vec_dot_cross(
    a: wp.array(dtype=wp.vec3),
    b: wp.array(dtype=wp.vec3),
    dot: wp.array(dtype=float),
    cross: wp.array(dtype=wp.vec3),
):
    i = wp.tid()
    dot[i] = wp.dot(a[i], b[i])
    cross[i] = wp.cross(a[i], b[i])


@wp.kernel
def vec_length_normalize(
    a: wp.array(dtype=wp.vec3), length: wp.array(dtype=float), unit: wp.array(dtype=wp.vec3)
):
    i = wp.tid()
    length[i] = wp.length(a[i])
    unit[i] = wp.normalize(a[i])


def _normalize_inputs(rng):
    a = _vecs(rng)
    a[0] = 0.0  # normalize of the zero vector is the zero vector
    return {"a": a, "length": np.zeros(N, np.float32), "unit": np.zeros((N, 3), np.float32)}


def _normalize_ref(ins):
    a = f64(ins["a"])
    n = np.linalg.norm(a, axis=1)
    unit = np.where(n[:, None] > 0, a / np.where(n == 0, 1, n)[:, None], 0.0)
    return {"length": n, "unit": unit}


@wp.kernel
def mat_vec(
    m: wp.array(dtype=wp.mat33),
    v: wp.array(dtype=wp.vec3),
    out: wp.array(dtype=wp.vec3),
    out2: wp.array(dtype=wp.vec3),
):
    i = wp.tid()
    out[i] = m[i] @ v[i]
    out2[i] = wp.mul(m[i], v[i])


@wp.kernel
def mat_mat(
    a: wp.array(dtype=wp.mat33), b: wp.array(dtype=wp.mat33), out: wp.array(dtype=wp.mat33)
):
    i = wp.tid()
    out[i] = a[i] @ b[i]


@wp.kernel
def mat_transpose_outer(
    m: wp.array(dtype=wp.mat33),
    a: wp.array(dtype=wp.vec3),
    b: wp.array(dtype=wp.vec3),
    t: wp.array(dtype=wp.mat33),
    o: wp.array(dtype=wp.mat33),
):
    i = wp.tid()
    t[i] = wp.transpose(m[i])
    o[i] = wp.outer(a[i], b[i])


@wp.kernel
def mat_construct_index(
    a: wp.array(dtype=float), out: wp.array(dtype=wp.mat33), diag: wp.array(dtype=float)
):
    i = wp.tid()
    x = a[i]
    m = wp.mat33(x, 1.0, 2.0, 3.0, x * 2.0, 4.0, 5.0, 6.0, x * 3.0)
    m[0, 2] = -x
    out[i] = m
    diag[i] = m[0, 0] + m[1][1] + m[2, 2]


def _mat_construct_ref(ins):
    x = f64(ins["a"])
    m = np.tile(np.array([[0, 1, 2], [3, 0, 4], [5, 6, 0]], np.float64), (len(x), 1, 1))
    m[:, 0, 0], m[:, 1, 1], m[:, 2, 2], m[:, 0, 2] = x, 2 * x, 3 * x, -x
    return {"out": m, "diag": 6 * x}


@wp.kernel
def vec3d_ops(
    a: wp.array(dtype=wp.vec3d), b: wp.array(dtype=wp.vec3d), out: wp.array(dtype=wp.float64)
):
    i = wp.tid()
    out[i] = wp.dot(wp.cross(a[i], b[i]), a[i] + b[i]) + wp.length(a[i])


def _zeros(*shape, dtype=np.float32):
    return np.zeros(shape, dtype)


CASES = [
    Case("vec_construct_splat", vec_construct, N,
         lambda rng: {"a": uniform(rng, N, -2, 2), "b": uniform(rng, N, -2, 2),
                      "c": uniform(rng, N, -2, 2), "out": _zeros(N, 3), "splat": _zeros(N, 3)},
         lambda ins: {"out": np.stack([f64(ins["a"]), f64(ins["b"]), f64(ins["c"])], 1),
                      "splat": np.repeat(f64(ins["a"])[:, None], 3, 1)}, ("out", "splat")),
    Case("vec_components", vec_components, N,
         lambda rng: {"v": _vecs(rng), "out": _zeros(N), "attrs": _zeros(N)},
         lambda ins: {"out": f64(ins["v"]) @ np.array([1.0, 2.0, 3.0]),
                      "attrs": f64(ins["v"])[:, 0] - f64(ins["v"])[:, 1] * f64(ins["v"])[:, 2]},
         ("out", "attrs")),
    Case("vec_component_assign", vec_assign, N,
         lambda rng: {"v": _vecs(rng), "out": _zeros(N, 3)},
         lambda ins: {"out": np.stack([f64(ins["v"])[:, 0] + f64(ins["v"])[:, 2],
                                       np.full(N, 5.0), f64(ins["v"])[:, 2]], 1)}, ("out",)),
    Case("vec_arith", vec_arith, N,
         lambda rng: {"a": _vecs(rng), "b": _vecs(rng), "s": uniform(rng, N, -2, 2),
                      "out": _zeros(N, 3)},
         lambda ins: {"out": (f64(ins["a"]) + f64(ins["b"])) * f64(ins["s"])[:, None]
                      - f64(ins["a"]) / 2 - f64(ins["b"])}, ("out",)),
    Case("vec_dot_cross", vec_dot_cross, N,
         lambda rng: {"a": _vecs(rng), "b": _vecs(rng), "dot": _zeros(N), "cross": _zeros(N, 3)},
         lambda ins: {"dot": np.sum(f64(ins["a"]) * f64(ins["b"]), 1),
                      "cross": np.cross(f64(ins["a"]), f64(ins["b"]))}, ("dot", "cross"),
         tol=(1e-5, 1e-5)),
    Case("vec_length_normalize", vec_length_normalize, N, _normalize_inputs, _normalize_ref,
         ("length", "unit")),
    Case("mat_vec", mat_vec, N,
         lambda rng: {"m": uniform(rng, (N, 3, 3), -2, 2), "v": _vecs(rng), "out": _zeros(N, 3),
                      "out2": _zeros(N, 3)},
         lambda ins: {"out": np.einsum("nij,nj->ni", f64(ins["m"]), f64(ins["v"])),
                      "out2": np.einsum("nij,nj->ni", f64(ins["m"]), f64(ins["v"]))},
         ("out", "out2"), tol=(1e-5, 1e-5)),
    Case("mat_mat", mat_mat, N,
         lambda rng: {"a": uniform(rng, (N, 3, 3), -2, 2), "b": uniform(rng, (N, 3, 3), -2, 2),
                      "out": _zeros(N, 3, 3)},
         lambda ins: {"out": f64(ins["a"]) @ f64(ins["b"])}, ("out",), tol=(1e-5, 1e-5)),
    Case("mat_transpose_outer", mat_transpose_outer, N,
         lambda rng: {"m": uniform(rng, (N, 3, 3), -2, 2), "a": _vecs(rng), "b": _vecs(rng),
                      "t": _zeros(N, 3, 3), "o": _zeros(N, 3, 3)},
         lambda ins: {"t": np.swapaxes(f64(ins["m"]), 1, 2),
                      "o": np.einsum("ni,nj->nij", f64(ins["a"]), f64(ins["b"]))}, ("t", "o")),
    Case("mat_construct_index", mat_construct_index, N,
         lambda rng: {"a": uniform(rng, N, -2, 2), "out": _zeros(N, 3, 3), "diag": _zeros(N)},
         _mat_construct_ref, ("out", "diag")),
    Case("vec3d_ops", vec3d_ops, N,
         lambda rng: {"a": uniform(rng, (N, 3), -2, 2, np.float64),
                      "b": uniform(rng, (N, 3), -2, 2, np.float64), "out": _zeros(N, dtype=np.float64)},
         lambda ins: {"out": np.sum(np.cross(ins["a"], ins["b"]) * (ins["a"] + ins["b"]), 1)
                      + np.linalg.norm(ins["a"], axis=1)}, ("out",), requires=("fp64",)),
]  # fmt: skip
