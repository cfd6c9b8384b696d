# ruff: noqa: UP018 - kernels keep Warp's idiom float(0.0) for a mutable local
"""``@func``: several returns, early return, overloads, calls of calls, constants, closures."""

import numpy as np

import kdsl as wp
from kdsl.testing.case import Case, f64, integers, uniform

N = 32

#: A module-level constant, read inside kernels as in Warp.
SCALE = wp.constant(2.5)
OFFSET = 0.25


@wp.func
def piecewise(x: float):
    if x < 0.0:
        return -x
    if x < 1.0:
        return x * x
    return 2.0 * x - 1.0


@wp.func
def first_multiple(n: int, m: int):
    # Early return from inside a loop of a func.
    for k in range(1, n + 1):
        if k % m == 0:
            return k
    return -1


@wp.func
def twice(x: float):
    return x * 2.0


@wp.func
def twice(x: int):  # noqa: F811 - an overload, as in Warp
    return x * 3


@wp.func
def twice(x: wp.vec3):  # noqa: F811
    return wp.vec3(x[0] * 4.0, x[1], x[2])


@wp.func
def hypot_sq(a: float, b: float):
    return twice(a * a) * 0.5 + b * b


@wp.func
def min_max(a: float, b: float):
    return wp.min(a, b), wp.max(a, b)


@wp.kernel
def func_returns(a: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = piecewise(a[i])


@wp.kernel
def func_early_return(
    n: wp.array(dtype=wp.int32), m: wp.array(dtype=wp.int32), out: wp.array(dtype=wp.int32)
):
    i = wp.tid()
    out[i] = first_multiple(n[i], m[i])


@wp.kernel
def func_overloads(
    a: wp.array(dtype=float),
    k: wp.array(dtype=wp.int32),
    v: wp.array(dtype=wp.vec3),
    fa: wp.array(dtype=float),
    fk: wp.array(dtype=wp.int32),
    fv: wp.array(dtype=wp.vec3),
):
    i = wp.tid()
    fa[i] = twice(a[i])
    fk[i] = twice(k[i])
    fv[i] = twice(v[i])


@wp.kernel
def func_nested_tuple(
    a: wp.array(dtype=float),
    b: wp.array(dtype=float),
    h: wp.array(dtype=float),
    lo: wp.array(dtype=float),
    hi: wp.array(dtype=float),
):
    i = wp.tid()
    h[i] = hypot_sq(a[i], b[i])
    x, y = min_max(a[i], b[i])
    lo[i] = x
    hi[i] = y


@wp.kernel
def module_constants(a: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = a[i] * SCALE + OFFSET


def _make_closure_kernel(power: int, bias: float):
    """Kernels built by a factory capture Python values from the enclosing scope."""

    @wp.kernel
    def closure_kernel(a: wp.array(dtype=float), out: wp.array(dtype=float)):
        i = wp.tid()
        s = float(1.0)
        for _k in range(power):
            s = s * a[i]
        out[i] = s + bias

    return closure_kernel


def _first_multiple_ref(ins):
    out = []
    for n, m in zip(ins["n"], ins["m"]):
        hits = [k for k in range(1, n + 1) if k % m == 0]
        out.append(hits[0] if hits else -1)
    return {"out": np.array(out)}


def _piecewise_ref(ins):
    x = f64(ins["a"])
    return {"out": np.where(x < 0, -x, np.where(x < 1, x * x, 2 * x - 1))}


def _overload_ref(ins):
    v = f64(ins["v"]).copy()
    v[:, 0] *= 4
    return {"fa": 2 * f64(ins["a"]), "fk": 3 * ins["k"].astype(np.int64), "fv": v}


CASES = [
    Case("func_multiple_returns", func_returns, N,
         lambda rng: {"a": uniform(rng, N, -2, 3), "out": np.zeros(N, np.float32)},
         _piecewise_ref, ("out",)),
    Case("func_early_return_in_loop", func_early_return, N,
         lambda rng: {"n": integers(rng, N, 0, 12), "m": integers(rng, N, 1, 7),
                      "out": np.zeros(N, np.int32)}, _first_multiple_ref, ("out",)),
    Case("func_overloads", func_overloads, N,
         lambda rng: {"a": uniform(rng, N, -2, 2), "k": integers(rng, N, -50, 50),
                      "v": uniform(rng, (N, 3), -2, 2), "fa": np.zeros(N, np.float32),
                      "fk": np.zeros(N, np.int32), "fv": np.zeros((N, 3), np.float32)},
         _overload_ref, ("fa", "fk", "fv")),
    Case("func_nested_calls_tuple_return", func_nested_tuple, N,
         lambda rng: {"a": uniform(rng, N, -2, 2), "b": uniform(rng, N, -2, 2),
                      "h": np.zeros(N, np.float32), "lo": np.zeros(N, np.float32),
                      "hi": np.zeros(N, np.float32)},
         lambda ins: {"h": f64(ins["a"]) ** 2 + f64(ins["b"]) ** 2,
                      "lo": np.minimum(ins["a"], ins["b"]), "hi": np.maximum(ins["a"], ins["b"])},
         ("h", "lo", "hi")),
    Case("module_constants", module_constants, N,
         lambda rng: {"a": uniform(rng, N, -2, 2), "out": np.zeros(N, np.float32)},
         lambda ins: {"out": f64(ins["a"]) * 2.5 + 0.25}, ("out",)),
    Case("closure_cube", _make_closure_kernel(3, 0.5), N,
         lambda rng: {"a": uniform(rng, N, -2, 2), "out": np.zeros(N, np.float32)},
         lambda ins: {"out": f64(ins["a"]) ** 3 + 0.5}, ("out",)),
    Case("closure_square", _make_closure_kernel(2, -1.0), N,
         lambda rng: {"a": uniform(rng, N, -2, 2), "out": np.zeros(N, np.float32)},
         lambda ins: {"out": f64(ins["a"]) ** 2 - 1.0}, ("out",)),
]  # fmt: skip
