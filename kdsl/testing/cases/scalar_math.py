"""Conformance cases: scalar math builtins at their edges (issue 5).

Every float builtin runs over float32 and float64 on inputs that mix ordinary values
with the edges: +-0, subnormals, the smallest normal and largest finite values,
+-1e+-30, +-inf, NaN and the domain limits. References are NumPy float64 on the
inputs as the kernel sees them, rounded to the output type (so an overflow to inf in
float32 is expected). Rules checked: ``clamp(NaN)`` is NaN (kdsl's choice; Warp
gives the lower bound), ``step(NaN) = 0``, ``nonzero(NaN) = 1``, ``sign(-0.0) = 1``,
``min``/``max`` skip NaN and order -0.0 below +0.0, ``abs(INT_MIN) = INT_MIN``.
"""

import math

import numpy as np

import kdsl as wp
from kdsl.ir import types as T
from kdsl.testing.case import Case, f64, uniform
from kdsl.testing.cases.dtype_rows import FLOAT_TYPES, dtype_row

N = 48


def edges(np_dtype) -> np.ndarray:
    """The edge values of a float type."""
    fi = np.finfo(np_dtype)
    tiny_sub = fi.smallest_subnormal
    with np.errstate(over="ignore"):  # +-1e30 overflow float16 to +-inf: also an edge
        return _edge_array(fi, tiny_sub, np_dtype)


def _edge_array(fi, tiny_sub, np_dtype) -> np.ndarray:
    return np.array([0.0, -0.0, tiny_sub, -tiny_sub, fi.smallest_normal, -fi.smallest_normal,
                     fi.max, -fi.max, np.inf, -np.inf, np.nan, 1e-30, -1e-30, 1e30, -1e30,
                     0.5, -0.5, 1.0, -1.0, 2.5, -2.5], np_dtype)  # fmt: skip


def _values(rng, np_dtype, lo: float, hi: float, extra=()) -> np.ndarray:
    a = uniform(rng, N, lo, hi, np.float64).astype(np_dtype)
    e = np.concatenate([edges(np_dtype), np.asarray(extra, np_dtype)])
    a[: len(e)] = e
    return a


def _rounded(ref, np_dtype):
    def apply(*xs):
        with np.errstate(all="ignore"):
            return np.asarray(ref(*xs), np.float64).astype(np_dtype)

    return apply


# --- float64 references of the inverse error functions (bisection on math.erf/erfc) ---

_erf = np.vectorize(math.erf, otypes=[np.float64])
_erfc = np.vectorize(math.erfc, otypes=[np.float64])


def _bisect_erfc(c: np.ndarray) -> np.ndarray:
    """The x >= 0 with erfc(x) = c, for c in (0, 1], by bisection (erfc is decreasing)."""
    lo, hi = np.zeros_like(c), np.full_like(c, 30.0)
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        big = _erfc(mid) > c
        lo, hi = np.where(big, mid, lo), np.where(big, hi, mid)
    return 0.5 * (lo + hi)


def _log_erfc_far(x: np.ndarray) -> np.ndarray:
    """log(erfc(x)) for x >= 5 by the continued fraction of erfc (no underflow)."""
    f = x.copy()
    for k in range(60, 0, -1):  # x + (k/2) / (x + ((k+1)/2) / ...), evaluated bottom-up
        f = x + (k / 2.0) / f
    return -x * x - np.log(f * math.sqrt(math.pi))


def _bisect_tail(c: np.ndarray) -> np.ndarray:
    """The x with erfc(x) = c for tiny c (down to subnormals), in log space."""
    lo, hi = np.full_like(c, 5.0), np.full_like(c, 30.0)
    log_c = np.log(c)
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        big = _log_erfc_far(mid) > log_c
        lo, hi = np.where(big, mid, lo), np.where(big, hi, mid)
    return 0.5 * (lo + hi)


def _bisect_erf(a: np.ndarray) -> np.ndarray:
    """The x >= 0 with erf(x) = a, for a in [0, 0.5]."""
    lo, hi = np.zeros_like(a), np.ones_like(a)
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        small = _erf(mid) < a
        lo, hi = np.where(small, mid, lo), np.where(small, hi, mid)
    return 0.5 * (lo + hi)


def ref_erfinv(y: np.ndarray) -> np.ndarray:
    """erfinv in float64: erf near 0, erfc (exact complement) elsewhere."""
    y = np.asarray(y, np.float64)
    a = np.abs(y)
    with np.errstate(all="ignore"):
        inner = np.clip(a, 0.0, 0.5)
        outer = np.clip(1.0 - a, 1e-300, 0.5)
        x = np.where(a <= 0.5, _bisect_erf(inner), _bisect_erfc(outer))
        x = np.where(a == 1.0, np.inf, x)
        x = np.where((a > 1.0) | np.isnan(a), np.nan, x)
    return np.copysign(x, y)


def ref_erfcinv(z: np.ndarray) -> np.ndarray:
    """erfcinv in float64 (``erfcinv(z) = -erfcinv(2 - z)`` above 1)."""
    z = np.asarray(z, np.float64)
    with np.errstate(all="ignore"):
        c = np.where(z > 1.0, 2.0 - z, z)
        clipped = np.clip(c, 5e-324, 1.0)
        x = np.where(c < 1e-200, _bisect_tail(clipped), _bisect_erfc(clipped))
        x = np.where(c == 0.0, np.inf, x)
        x = np.where(z > 1.0, -x, x)
        x = np.where((c < 0.0) | np.isnan(z), np.nan, x)
    return x


# --- unary float builtins ---------------------------------------------------------------


def _unary_kernel(fn, dtype):
    @wp.kernel
    def unary(a: wp.array(dtype=dtype), out: wp.array(dtype=dtype)):
        i = wp.tid()
        out[i] = fn(a[i])

    return unary


def _sign_ref(x):
    return np.where(x < 0, -1.0, 1.0)


#: name -> (builtin, (lo, hi) of the random inputs, extra edges, float64 reference)
_UNARY = {
    "frac": (wp.frac, (-20, 20), (7.75, -7.75), lambda x: x - np.trunc(x)),
    "degrees": (wp.degrees, (-7, 7), (math.pi,), np.degrees),
    "radians": (wp.radians, (-400, 400), (180.0,), np.radians),
    "step": (wp.step, (-3, 3), (), lambda x: np.where(x < 0, 1.0, 0.0)),
    "nonzero": (wp.nonzero, (-3, 3), (), lambda x: np.where(x != 0, 1.0, 0.0)),
    "erfinv": (wp.erfinv, (-1, 1), (0.999999, -0.9999, 0.3, 1.5), ref_erfinv),
    "erfcinv": (wp.erfcinv, (0, 2), (1e-20, 1.9999, 1.5, 3.0), ref_erfcinv),
    "cbrt": (wp.cbrt, (-100, 100), (27.0, -8.0), np.cbrt),
    "exp2": (wp.exp2, (-30, 30), (-149.0, 127.5, 1023.5), np.exp2),
    "log2": (wp.log2, (0, 100), (1024.0,), np.log2),
    "log10": (wp.log10, (0, 1000), (1000.0,), np.log10),
    "asin": (wp.asin, (-1, 1), (0.99999,), np.arcsin),
    "acos": (wp.acos, (-1, 1), (0.99999,), np.arccos),
    "atan": (wp.atan, (-50, 50), (), np.arctan),
    "sinh": (wp.sinh, (-10, 10), (89.0, -89.0), np.sinh),
    "cosh": (wp.cosh, (-10, 10), (89.0, -89.0), np.cosh),
    "tanh": (wp.tanh, (-10, 10), (20.0,), np.tanh),
    "erf": (wp.erf, (-4, 4), (6.0, -6.0), lambda x: _erf(x)),
    "erfc": (wp.erfc, (-4, 4), (9.0, 6.0), lambda x: _erfc(x)),
    "trunc": (wp.trunc, (-9, 9), (-0.75, 0.75, 8388607.5), np.trunc),
    "floor": (wp.floor, (-9, 9), (-0.75, 0.75, 8388607.5), np.floor),
    "ceil": (wp.ceil, (-9, 9), (-0.75, 0.75, 8388607.5), np.ceil),
    "round": (wp.round, (-9, 9), (-1.5, 1.5, 0.49999997, 8388607.5),
              lambda x: np.sign(x) * np.floor(np.abs(x) + 0.5)),
    "rint": (wp.rint, (-9, 9), (-1.5, 1.5, 0.49999997, 8388607.5), np.rint),
    "sign": (wp.sign, (-3, 3), (), _sign_ref),
    "abs": (wp.abs, (-3, 3), (), np.abs),
    "sqrt": (wp.sqrt, (0, 100), (4.0,), np.sqrt),
    "exp": (wp.exp, (-20, 20), (88.0, 89.0, -104.0, 709.0), np.exp),
    "log": (wp.log, (0, 100), (math.e,), np.log),
    "sin": (wp.sin, (-7, 7), (math.pi,), np.sin),
    "cos": (wp.cos, (-7, 7), (math.pi,), np.cos),
}  # fmt: skip

#: Outputs of libm-backed functions with huge arguments (sin(1e30)) depend on the
#: argument reduction: compare those within a looser absolute bound.
_LOOSE = {"sin": (1e-5, 1e-5), "cos": (1e-5, 1e-5)}


def _unary_cases() -> list[Case]:
    out = []
    for tname, dtype, np_dtype, req in FLOAT_TYPES:
        for name, (fn, (lo, hi), extra, ref) in _UNARY.items():

            def make(rng, np_dtype=np_dtype, lo=lo, hi=hi, extra=extra):
                return {"a": _values(rng, np_dtype, lo, hi, extra), "out": np.zeros(N, np_dtype)}

            def reference(ins, ref=ref, np_dtype=np_dtype):
                return {"out": _rounded(ref, np_dtype)(f64(ins["a"]))}

            tol = _LOOSE.get(name) if np_dtype == np.float32 else None
            out.append(Case(f"sm_{name}_{tname}", _unary_kernel(fn, dtype), N, make, reference,
                            ("out",), requires=req, tol=tol))  # fmt: skip
    return out


#: float16 runs the builtins whose float16 form is kdsl code or a widened intrinsic.
_HALF_OPS = ("frac", "degrees", "radians", "step", "nonzero", "erfinv", "erfcinv", "sign",
             "abs", "floor", "round", "sqrt", "exp")  # fmt: skip


def _half_cases() -> list[Case]:
    out = []
    for name in _HALF_OPS:
        fn, (lo, hi), extra, ref = _UNARY[name]
        extra = [e for e in extra if abs(e) < 60000.0]

        def make(rng, lo=lo, hi=hi, extra=tuple(extra)):
            return {"a": _values(rng, np.float16, lo, hi, extra), "out": np.zeros(N, np.float16)}

        out.append(Case(f"sm_{name}_f16", _unary_kernel(fn, wp.float16), N, make,
                        lambda ins, ref=ref: {"out": _rounded(ref, np.float16)(f64(ins["a"]))},
                        ("out",), requires=("fp16",)))  # fmt: skip
    return out


# --- rounding on vectors -------------------------------------------------------------------


def _vec_kernel(fn, vtype):
    @wp.kernel
    def vec_unary(a: wp.array(dtype=vtype), out: wp.array(dtype=vtype)):
        i = wp.tid()
        out[i] = fn(a[i])

    return vec_unary


def _vector_cases() -> list[Case]:
    out = []
    table = {"floor": np.floor, "ceil": np.ceil, "trunc": np.trunc, "rint": np.rint,
             "round": _UNARY["round"][3], "frac": _UNARY["frac"][3], "sign": _sign_ref,
             "abs": np.abs}  # fmt: skip
    for tname, dtype, np_dtype, req in FLOAT_TYPES:
        vtype = wp.vector(3, dtype)
        for name, ref in table.items():
            fn = getattr(wp, name)

            def make(rng, np_dtype=np_dtype):
                a = _values(rng, np_dtype, -6, 6, (-0.5, 0.5, 1.5, -2.5)).reshape(16, 3)
                return {"a": a, "out": np.zeros((16, 3), np_dtype)}

            out.append(Case(f"sm_vec3_{name}_{tname}", _vec_kernel(fn, vtype), 16, make,
                            lambda ins, ref=ref, d=np_dtype: {"out": _rounded(ref, d)(f64(ins["a"]))},
                            ("out",), requires=req))  # fmt: skip
    return out


# --- integers --------------------------------------------------------------------------------

_INTS = tuple(dtype_row(t)[:3] for t in (T.I8, T.I16, T.I32, T.I64, T.U8, T.U32, T.U64))


def _int_values(rng, np_dtype) -> np.ndarray:
    info = np.iinfo(np_dtype)
    a = rng.integers(info.min, info.max, size=N, dtype=np_dtype, endpoint=True)
    e = [info.min, info.max, 0, 1, info.min + 1, info.max - 1] + ([-1, -2] if info.min else [2])
    a[: len(e)] = np.array(e, dtype=np_dtype)
    return a


def _int_kernel(dtype):
    @wp.kernel
    def int_ops(a: wp.array(dtype=dtype), b: wp.array(dtype=dtype),
                absolute: wp.array(dtype=dtype), sign: wp.array(dtype=dtype),
                step: wp.array(dtype=dtype), nonzero: wp.array(dtype=dtype),
                clamped: wp.array(dtype=dtype), bits: wp.array(dtype=wp.int32)):  # fmt: skip
        i = wp.tid()
        x = a[i]
        absolute[i] = wp.abs(x)
        sign[i] = wp.sign(x)
        step[i] = wp.step(x)
        nonzero[i] = wp.nonzero(x)
        clamped[i] = wp.clamp(x, wp.min(b[i], dtype(100)), dtype(100))
        bits[i] = wp.bit_count(x)

    return int_ops


def _popcount(a: np.ndarray) -> np.ndarray:
    u = a.view(np.dtype(f"u{a.dtype.itemsize}")).astype(np.uint64)
    return np.array([bin(int(v)).count("1") for v in u], np.int64)


def _int_cases() -> list[Case]:
    out = []
    for tname, dtype, np_dtype in _INTS:

        def make(rng, np_dtype=np_dtype):
            z = np.zeros(N, np_dtype)
            return {"a": _int_values(rng, np_dtype), "b": _int_values(rng, np_dtype)[::-1].copy(),
                    "absolute": z, "sign": z.copy(), "step": z.copy(), "nonzero": z.copy(),
                    "clamped": z.copy(), "bits": np.zeros(N, np.int32)}  # fmt: skip

        def reference(ins, np_dtype=np_dtype):
            a, b = ins["a"], ins["b"]
            signed = np.iinfo(np_dtype).min < 0
            with np.errstate(all="ignore"):
                absolute = np.abs(a) if signed else a  # abs(MIN) wraps to MIN
            lo = np.minimum(b, np_dtype(100))
            return {"absolute": absolute, "sign": np.where(a < 0, -1, 1).astype(np_dtype),
                    "step": (a < 0).astype(np_dtype), "nonzero": (a != 0).astype(np_dtype),
                    "clamped": np.minimum(np.maximum(a, lo), np_dtype(100)),
                    "bits": _popcount(a)}  # fmt: skip

        out.append(Case(f"sm_int_ops_{tname}", _int_kernel(dtype), N, make, reference,
                        ("absolute", "sign", "step", "nonzero", "clamped", "bits")))  # fmt: skip
    return out


# --- clamp, lerp, smoothstep -------------------------------------------------------------------


def _ternary_kernel(fn, dtype):
    @wp.kernel
    def ternary(a: wp.array(dtype=dtype), b: wp.array(dtype=dtype), c: wp.array(dtype=dtype),
                out: wp.array(dtype=dtype)):  # fmt: skip
        i = wp.tid()
        out[i] = fn(a[i], b[i], c[i])

    return ternary


def _clamp_ref(x, lo, hi):
    return np.where(np.isnan(x), np.nan, np.fmin(np.fmax(x, lo), hi))


def _smoothstep_ref(a, b, x):
    with np.errstate(all="ignore"):
        t = (x - a) / (b - a)
    t = _clamp_ref(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _ternary_inputs(kind: str):
    def make(rng, np_dtype):
        x = _values(rng, np_dtype, -3, 3)
        lo = uniform(rng, N, -2, 0, np_dtype)
        hi = uniform(rng, N, 0, 2, np_dtype)
        lo[:6] = [-1.0, 1.0, -np.inf, 0.0, np.nan, -0.0]  # lo > hi, infinite/NaN bounds
        hi[:6] = [1.0, -1.0, np.inf, 0.0, 1.0, 0.0]
        if kind == "lerp":  # (a, b, t): finite ends, t with edges
            a, b = uniform(rng, N, -5, 5, np_dtype), uniform(rng, N, -5, 5, np_dtype)
            t = _values(rng, np_dtype, -0.5, 1.5)
            t[np.abs(t) > 1e6] = 2.0  # a*(1-t) would overflow before the sum
            return {"a": a, "b": b, "c": t, "out": np.zeros(N, np_dtype)}
        if kind == "smoothstep":  # (edge0, edge1, x)
            return {"a": lo, "b": hi, "c": x, "out": np.zeros(N, np_dtype)}
        return {"a": x, "b": lo, "c": hi, "out": np.zeros(N, np_dtype)}

    return make


_TERNARY = {
    "clamp": (wp.clamp, _clamp_ref),
    "lerp": (wp.lerp, lambda a, b, t: a * (1.0 - t) + b * t),
    "smoothstep": (wp.smoothstep, _smoothstep_ref),
}


def _ternary_cases() -> list[Case]:
    out = []
    for tname, dtype, np_dtype, req in FLOAT_TYPES:
        for name, (fn, ref) in _TERNARY.items():
            gen = _ternary_inputs(name)
            out.append(Case(
                f"sm_{name}_{tname}", _ternary_kernel(fn, dtype), N,
                lambda rng, gen=gen, d=np_dtype: gen(rng, d),
                lambda ins, ref=ref, d=np_dtype: {"out": _rounded(ref, d)(
                    f64(ins["a"]), f64(ins["b"]), f64(ins["c"]))},
                ("out",), requires=req))  # fmt: skip
    return out


@wp.kernel
def lerp_composites(a: wp.array(dtype=wp.vec3), b: wp.array(dtype=wp.vec3),
                    ma: wp.array(dtype=wp.mat22), mb: wp.array(dtype=wp.mat22),
                    t: wp.array(dtype=float), v: wp.array(dtype=wp.vec3),
                    m: wp.array(dtype=wp.mat22), q: wp.array(dtype=wp.quat)):  # fmt: skip
    i = wp.tid()
    v[i] = wp.lerp(a[i], b[i], t[i])
    m[i] = wp.lerp(ma[i], mb[i], t[i])
    q[i] = wp.lerp(wp.quat(a[i], 1.0), wp.quat(b[i], 0.0), t[i])


def _lerp_composites_inputs(rng):
    return {"a": uniform(rng, (N, 3), -3, 3), "b": uniform(rng, (N, 3), -3, 3),
            "ma": uniform(rng, (N, 2, 2), -3, 3), "mb": uniform(rng, (N, 2, 2), -3, 3),
            "t": uniform(rng, N, -0.5, 1.5), "v": np.zeros((N, 3), np.float32),
            "m": np.zeros((N, 2, 2), np.float32), "q": np.zeros((N, 4), np.float32)}  # fmt: skip


def _lerp_composites_ref(ins):
    t = f64(ins["t"])
    a, b = f64(ins["a"]), f64(ins["b"])
    qa = np.concatenate([a, np.ones((N, 1))], axis=1)
    qb = np.concatenate([b, np.zeros((N, 1))], axis=1)
    return {"v": a * (1 - t)[:, None] + b * t[:, None],
            "m": f64(ins["ma"]) * (1 - t)[:, None, None] + f64(ins["mb"]) * t[:, None, None],
            "q": qa * (1 - t)[:, None] + qb * t[:, None]}  # fmt: skip


@wp.kernel
def clamp_vec3(x: wp.array(dtype=wp.vec3d), out: wp.array(dtype=wp.vec3d)):
    i = wp.tid()
    out[i] = wp.clamp(x[i], wp.vec3d(-1.0), wp.vec3d(1.0))


# --- predicates, min/max, binary math --------------------------------------------------------


def _pred_kernel(dtype):
    vtype = wp.vector(3, dtype)
    mtype = wp.matrix((2, 2), dtype)

    @wp.kernel
    def predicates(a: wp.array(dtype=dtype), v: wp.array(dtype=vtype), m: wp.array(dtype=mtype),
                   out: wp.array2d(dtype=wp.int32)):  # fmt: skip
        i = wp.tid()
        out[i, 0] = wp.int32(wp.isnan(a[i]))
        out[i, 1] = wp.int32(wp.isinf(a[i]))
        out[i, 2] = wp.int32(wp.isfinite(a[i]))
        out[i, 3] = wp.int32(wp.isnan(v[i]))
        out[i, 4] = wp.int32(wp.isinf(v[i]))
        out[i, 5] = wp.int32(wp.isfinite(v[i]))
        out[i, 6] = wp.int32(wp.isnan(m[i])) + 2 * wp.int32(wp.isfinite(m[i]))

    return predicates


def _pred_cases() -> list[Case]:
    out = []
    for tname, dtype, np_dtype, req in FLOAT_TYPES:

        def make(rng, d=np_dtype):
            a = _values(rng, d, -3, 3)
            return {"a": a, "v": rng.permutation(np.concatenate([a, a, a])).reshape(N, 3),
                    "m": rng.permutation(np.concatenate([a] * 4)).reshape(N, 2, 2),
                    "out": np.zeros((N, 7), np.int32)}  # fmt: skip

        def reference(ins):
            a, v, m = f64(ins["a"]), f64(ins["v"]), f64(ins["m"]).reshape(N, 4)
            cols = [np.isnan(a), np.isinf(a), np.isfinite(a), np.isnan(v).any(1),
                    np.isinf(v).any(1), np.isfinite(v).all(1),
                    np.isnan(m).any(1) + 2 * np.isfinite(m).all(1)]  # fmt: skip
            return {"out": np.stack(cols, axis=1).astype(np.int32)}

        out.append(Case(f"sm_predicates_{tname}", _pred_kernel(dtype), N, make, reference,
                        ("out",), requires=req))  # fmt: skip
    return out


def _minmax_kernel(dtype):
    vtype = wp.vector(4, dtype)

    @wp.kernel
    def minmax(a: wp.array(dtype=dtype), b: wp.array(dtype=dtype), v: wp.array(dtype=vtype),
               out: wp.array2d(dtype=dtype)):  # fmt: skip
        i = wp.tid()
        lo = wp.min(a[i], b[i])
        hi = wp.max(a[i], b[i])
        out[i, 0] = lo
        out[i, 1] = hi
        # The sign of a zero result is observable through copysign.
        out[i, 2] = wp.copysign(dtype(1.0), lo)
        out[i, 3] = wp.copysign(dtype(1.0), hi)
        out[i, 4] = wp.min(v[i])
        out[i, 5] = wp.max(v[i])
        out[i, 6] = wp.min(a[i], b[i], v[i][0], v[i][1])

    return minmax


def _zero_sign(x):
    return np.copysign(1.0, x)


def _minmax_cases() -> list[Case]:
    out = []
    for tname, dtype, np_dtype, req in FLOAT_TYPES:

        def make(rng, d=np_dtype):
            a = _values(rng, d, -3, 3)
            b = rng.permutation(a)
            a[:4], b[:4] = [0.0, -0.0, np.nan, np.nan], [-0.0, 0.0, 1.0, np.nan]
            v = uniform(rng, (N, 4), -3, 3, d)
            v[::5, 1] = np.nan
            v[::7, :] = np.nan
            return {"a": a, "b": b, "v": v, "out": np.zeros((N, 7), d)}

        def reference(ins):
            a, b, v = f64(ins["a"]), f64(ins["b"]), f64(ins["v"])
            lo, hi = np.fmin(a, b), np.fmax(a, b)
            both_zero = (a == 0) & (b == 0)
            lo_sign = np.where(both_zero, np.where(np.signbit(a) | np.signbit(b), -1.0, 1.0),
                               _zero_sign(lo))  # fmt: skip
            hi_sign = np.where(both_zero, np.where(np.signbit(a) & np.signbit(b), -1.0, 1.0),
                               _zero_sign(hi))  # fmt: skip
            with np.errstate(all="ignore"):
                vmin, vmax = np.fmin.reduce(v, axis=1), np.fmax.reduce(v, axis=1)
                m4 = np.fmin.reduce(np.stack([a, b, v[:, 0], v[:, 1]], 1), axis=1)
            return {"out": np.stack([lo, hi, lo_sign, hi_sign, vmin, vmax, m4], axis=1)}

        out.append(Case(f"sm_minmax_{tname}", _minmax_kernel(dtype), N, make, reference,
                        ("out",), requires=req))  # fmt: skip
    return out


def _binary_kernel(dtype):
    @wp.kernel
    def binary(a: wp.array(dtype=dtype), b: wp.array(dtype=dtype), out: wp.array2d(dtype=dtype)):
        i = wp.tid()
        out[i, 0] = wp.copysign(a[i], b[i])
        out[i, 1] = wp.atan2(a[i], b[i])
        out[i, 2] = wp.pow(a[i], b[i])

    return binary


def _binary_cases() -> list[Case]:
    out = []
    for tname, dtype, np_dtype, req in FLOAT_TYPES:

        def make(rng, d=np_dtype):
            a = _values(rng, d, -3, 3)
            b = _values(rng, d, -3, 3)[::-1].copy()
            a[:8] = [0.0, -8.0, 1.0, np.nan, 0.0, -0.0, 2.0, -1.0]
            b[:8] = [-1.0, 1.0 / 3.0, np.nan, 0.0, -0.0, -0.0, 0.5, np.inf]
            return {"a": a, "b": b, "out": np.zeros((N, 3), d)}

        def reference(ins, d=np_dtype):
            a, b = f64(ins["a"]), f64(ins["b"])
            with np.errstate(all="ignore"):
                cols = [np.copysign(a, b), np.arctan2(a, b), np.power(a, b)]
            return {"out": np.stack(cols, axis=1).astype(d)}

        out.append(Case(f"sm_binary_{tname}", _binary_kernel(dtype), N, make, reference,
                        ("out",), requires=req))  # fmt: skip
    return out


CASES: list[Case] = [
    *_unary_cases(),
    *_half_cases(),
    *_vector_cases(),
    *_int_cases(),
    *_ternary_cases(),
    *_pred_cases(),
    *_minmax_cases(),
    *_binary_cases(),
    Case("sm_lerp_composites", lerp_composites, N, _lerp_composites_inputs,
         _lerp_composites_ref, ("v", "m", "q")),
    Case("sm_clamp_vec3d", clamp_vec3, 16,
         lambda rng: {"x": _values(rng, np.float64, -3, 3).reshape(16, 3),
                      "out": np.zeros((16, 3))},
         lambda ins: {"out": _clamp_ref(ins["x"], -1.0, 1.0)}, ("out",), requires=("fp64",)),
]  # fmt: skip
