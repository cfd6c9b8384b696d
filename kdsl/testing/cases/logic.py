# ruff: noqa: UP018 - kernels keep Warp's idiom float(0.0) for a mutable local
"""Comparisons, bool logic (with short-circuit evaluation) and casts."""

import numpy as np

import kdsl as wp
from kdsl.testing.case import Case, f64, integers, uniform

N = 48


def _compare_kernel(dtype):
    @wp.kernel
    def compare(
        a: wp.array(dtype=dtype), b: wp.array(dtype=dtype), out: wp.array2d(dtype=wp.int32)
    ):
        i = wp.tid()
        x = a[i]
        y = b[i]
        out[i, 0] = wp.int32(x == y)
        out[i, 1] = wp.int32(x != y)
        out[i, 2] = wp.int32(x < y)
        out[i, 3] = wp.int32(x <= y)
        out[i, 4] = wp.int32(x > y)
        out[i, 5] = wp.int32(x >= y)

    return compare


def _compare_ref(ins):
    a, b = f64(ins["a"]), f64(ins["b"])
    cols = [a == b, a != b, a < b, a <= b, a > b, a >= b]
    return {"out": np.stack(cols, axis=1).astype(np.int32)}


def _compare_inputs(np_dtype):
    def make(rng):
        # Few distinct values, so equality happens often.
        a = integers(rng, N, -3, 4).astype(np_dtype)
        b = integers(rng, N, -3, 4).astype(np_dtype)
        return {"a": a, "b": b, "out": np.zeros((N, 6), np.int32)}

    return make


@wp.kernel
def bool_logic(
    a: wp.array(dtype=wp.int32), b: wp.array(dtype=wp.int32), out: wp.array2d(dtype=wp.int32)
):
    i = wp.tid()
    p = a[i] > 0
    q = b[i] > 0
    out[i, 0] = wp.int32(p and q)
    out[i, 1] = wp.int32(p or q)
    out[i, 2] = wp.int32(not p)
    out[i, 3] = wp.int32((p and not q) or (q and not p))
    r = False
    if p and (q or a[i] > 5):
        r = True
    out[i, 4] = wp.int32(r)


def _bool_ref(ins):
    p, q = ins["a"] > 0, ins["b"] > 0
    cols = [p & q, p | q, ~p, p ^ q, p & (q | (ins["a"] > 5))]
    return {"out": np.stack(cols, axis=1).astype(np.int32)}


@wp.kernel
def short_circuit(a: wp.array(dtype=float), out: wp.array(dtype=float)):
    # Threads past the end of ``a`` must not read it: ``and``/``or`` stop early.
    i = wp.tid()
    n = a.shape[0]
    v = float(0.0)
    if i < n and a[i] > 0.0:
        v = 1.0
    if i >= n or a[i] < 0.5:
        v = v + 10.0
    out[i] = v


def _short_ref(ins):
    a = f64(ins["a"])
    n = a.shape[0]
    m = ins["out"].shape[0]
    v = np.zeros(m)
    v[:n] += a > 0.0
    low = np.ones(m, bool)
    low[:n] = a < 0.5
    return {"out": v + 10.0 * low}


@wp.kernel
def cast_f32_to_int(
    a: wp.array(dtype=float),
    i32: wp.array(dtype=wp.int32),
    u32: wp.array(dtype=wp.uint32),
    i8: wp.array(dtype=wp.int8),
):
    i = wp.tid()
    i32[i] = wp.int32(a[i])
    u32[i] = wp.uint32(a[i])
    i8[i] = wp.int8(a[i])


def _saturate(x: np.ndarray, dtype) -> np.ndarray:
    info = np.iinfo(dtype)
    t = np.trunc(np.where(np.isnan(x), 0.0, x))
    return np.clip(t, info.min, info.max).astype(np.int64)


def _cast_inputs(rng):
    a = uniform(rng, 32, -300.0, 300.0)
    special = [np.nan, np.inf, -np.inf, 3e9, -3e9, 5e9, 0.5, -0.5, 1.999, -1.999, 127.9, -128.9]
    a[: len(special)] = np.array(special, np.float32)
    return {"a": a, "i32": np.zeros(32, np.int32), "u32": np.zeros(32, np.uint32),
            "i8": np.zeros(32, np.int8)}  # fmt: skip


def _cast_ref(ins):
    x = f64(ins["a"])
    return {"i32": _saturate(x, np.int32), "u32": _saturate(x, np.uint32),
            "i8": _saturate(x, np.int8)}  # fmt: skip


@wp.kernel
def cast_int_to_float(
    a: wp.array(dtype=wp.int32),
    f: wp.array(dtype=float),
    w: wp.array(dtype=wp.uint8),
    b: wp.array(dtype=wp.int32),
):
    i = wp.tid()
    f[i] = float(a[i]) * 0.5
    w[i] = wp.uint8(a[i])  # integer to integer casts wrap
    b[i] = wp.int32(wp.bool(a[i]))


def _int_cast_ref(ins):
    a = ins["a"].astype(np.int64)
    return {"f": f64(a) * 0.5, "w": a & 0xFF, "b": (a != 0).astype(np.int64)}


@wp.kernel
def cast_f64_f32(
    a: wp.array(dtype=wp.float64),
    b: wp.array(dtype=float),
    down: wp.array(dtype=float),
    up: wp.array(dtype=wp.float64),
):
    i = wp.tid()
    down[i] = wp.float32(a[i])
    up[i] = wp.float64(b[i]) * wp.float64(3.0)


CASES = [
    Case("compare_f32", _compare_kernel(wp.float32), N, _compare_inputs(np.float32),
         _compare_ref, ("out",)),
    Case("compare_i32", _compare_kernel(wp.int32), N, _compare_inputs(np.int32),
         _compare_ref, ("out",)),
    Case("compare_f64", _compare_kernel(wp.float64), N, _compare_inputs(np.float64),
         _compare_ref, ("out",), requires=("fp64",)),
    Case("bool_logic", bool_logic, N,
         lambda rng: {"a": integers(rng, N, -8, 9), "b": integers(rng, N, -8, 9),
                      "out": np.zeros((N, 5), np.int32)},
         _bool_ref, ("out",)),
    Case("short_circuit_bounds", short_circuit, 40,
         lambda rng: {"a": uniform(rng, 24, -1.0, 1.0), "out": np.zeros(40, np.float32)},
         _short_ref, ("out",)),
    Case("cast_float_to_int_saturating", cast_f32_to_int, 32, _cast_inputs, _cast_ref,
         ("i32", "u32", "i8")),
    Case("cast_int_to_float_and_wrap", cast_int_to_float, N,
         lambda rng: {"a": integers(rng, N, -100000, 100000), "f": np.zeros(N, np.float32),
                      "w": np.zeros(N, np.uint8), "b": np.zeros(N, np.int32)},
         _int_cast_ref, ("f", "w", "b")),
    Case("cast_f64_f32", cast_f64_f32, N,
         lambda rng: {"a": uniform(rng, N, -1e3, 1e3, np.float64), "b": uniform(rng, N, -5, 5),
                      "down": np.zeros(N, np.float32), "up": np.zeros(N, np.float64)},
         lambda ins: {"down": f64(ins["a"]), "up": f64(ins["b"]) * 3.0}, ("down", "up"),
         requires=("fp64",)),
]  # fmt: skip
