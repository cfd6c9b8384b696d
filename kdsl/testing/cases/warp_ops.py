"""Conformance cases: Warp's operator-named builtins, constants, ``reversed``, ``cast``,
``block_dim``, ``lower_bound`` and the edge/triangle queries (issue 14).

References are NumPy float64 (or exact integers) computed independently of kdsl:
``add(a, b)`` against ``a + b``, ``mod`` against ``np.fmod``, ``cast`` against
``ndarray.view``, ``lower_bound`` against Warp's search of ``[begin, end - 1]``, the
segment query against a float64 transcription of Warp's algorithm and
``intersect_tri_tri`` against a float64 separating-axis test.
"""

import math

import numpy as np

import kdsl as wp
from kdsl.testing.case import Case, f64, integers, uniform
from kdsl.testing.cases.dtype_rows import FLOAT_TYPES, INT_TYPES

N = 32


def _float_ops_kernel(dtype):
    @wp.kernel
    def float_operator_builtins(a: wp.array(dtype=dtype), b: wp.array(dtype=dtype),
                                out: wp.array2d(dtype=dtype)):  # fmt: skip
        i = wp.tid()
        x = a[i]
        y = b[i]
        out[i, 0] = wp.add(x, y)
        out[i, 1] = wp.sub(x, y)
        out[i, 2] = wp.mul(x, y)
        out[i, 3] = wp.div(x, y)
        out[i, 4] = wp.floordiv(x, y)
        out[i, 5] = wp.mod(x, y)
        out[i, 6] = wp.neg(x)
        out[i, 7] = wp.pos(y)
        out[i, 8] = wp.div_approx(x, y)
        out[i, 9] = dtype(wp.unot(x))
        out[i, 10] = x * wp.pi + wp.e - wp.tau / wp.half_pi + wp.ln2 * wp.LN10
        out[i, 11] = (
            wp.log2e * wp.log10e + wp.PHI - dtype(wp.isinf(wp.inf)) + dtype(wp.isnan(wp.NAN))
        )

    return float_operator_builtins


def _float_ops_inputs(np_dtype):
    def make(rng):
        a = uniform(rng, N, -10.0, 10.0, np_dtype)
        b = uniform(rng, N, 0.5, 4.0, np_dtype) * np.where(rng.random(N) < 0.5, -1, 1).astype(
            np_dtype
        )
        a[0] = 0.0
        return {"a": a, "b": b, "out": np.zeros((N, 12), np_dtype)}

    return make


def _float_ops_ref(ins):
    a, b = f64(ins["a"]), f64(ins["b"])
    out = np.zeros((len(a), 12))
    out[:, 0], out[:, 1], out[:, 2], out[:, 3] = a + b, a - b, a * b, a / b
    out[:, 4], out[:, 5], out[:, 6], out[:, 7] = np.floor(a / b), np.fmod(a, b), -a, b
    out[:, 8], out[:, 9] = a / b, (a == 0).astype(np.float64)
    out[:, 10] = a * math.pi + math.e - 2 * math.pi / (math.pi / 2) + math.log(2) * math.log(10)
    out[:, 11] = math.log2(math.e) * math.log10(math.e) + (1 + math.sqrt(5)) / 2 - 1 + 1
    return {"out": out}


def _int_ops_kernel(dtype):
    @wp.kernel
    def int_operator_builtins(a: wp.array(dtype=dtype), b: wp.array(dtype=dtype),
                              s: wp.array(dtype=dtype), out: wp.array2d(dtype=dtype)):  # fmt: skip
        i = wp.tid()
        x = a[i]
        y = b[i]
        out[i, 0] = wp.add(x, y)
        out[i, 1] = wp.sub(x, y)
        out[i, 2] = wp.div(x, y)
        out[i, 3] = wp.floordiv(x, y)
        out[i, 4] = wp.mod(x, y)
        out[i, 5] = wp.bit_and(x, y)
        out[i, 6] = wp.bit_or(x, y)
        out[i, 7] = wp.bit_xor(x, y)
        out[i, 8] = wp.lshift(x, s[i])
        out[i, 9] = wp.rshift(x, s[i])
        out[i, 10] = wp.invert(x)
        out[i, 11] = dtype(wp.unot(x))
        out[i, 12] = wp.neg(wp.neg(x))

    return int_operator_builtins


def _int_ops_inputs(np_dtype):
    signed = np.iinfo(np_dtype).min < 0

    def make(rng):
        lo = -1000 if signed else 0
        a = integers(rng, N, lo, 1000, np_dtype)
        b = integers(rng, N, 1, 50, np_dtype)
        if signed:
            b = (b.astype(np.int64) * np.where(rng.random(N) < 0.5, -1, 1)).astype(np_dtype)
        a[0] = 0
        return {"a": a, "b": b, "s": integers(rng, N, 0, 8, np_dtype),
                "out": np.zeros((N, 13), np_dtype)}  # fmt: skip

    return make


def _int_ops_ref(ins):
    dt = ins["a"].dtype
    bits = np.iinfo(dt).bits
    rows = []
    for x, y, s in zip(ins["a"].tolist(), ins["b"].tolist(), ins["s"].tolist()):
        q = abs(x) // abs(y) * (1 if (x < 0) == (y < 0) else -1)
        rows.append([x + y, x - y, q, x // y, x - q * y, x & y, x | y, x ^ y, x << s, x >> s,
                     ~x, int(x == 0), x])  # fmt: skip
    span = 1 << bits
    lo = int(np.iinfo(dt).min)
    return {"out": np.array([[(v - lo) % span + lo for v in r] for r in rows], dt)}


@wp.kernel
def vector_operator_builtins(a: wp.array(dtype=wp.vec3), b: wp.array(dtype=wp.vec3),
                             k: wp.array(dtype=wp.vec3i), out: wp.array2d(dtype=float)):  # fmt: skip
    i = wp.tid()
    r = wp.add(a[i], b[i])
    r = wp.sub(r, wp.div(a[i], 2.0))
    r = wp.add(r, wp.div(2.0, b[i]))
    r = wp.add(r, wp.mod(a[i], b[i]))
    r = wp.add(r, wp.neg(b[i]))
    iv = wp.bit_xor(wp.invert(k[i]), wp.lshift(k[i], wp.vec3i(1, 2, 3)))
    for c in range(3):
        out[i, c] = r[c]
        out[i, 3 + c] = float(iv[c])


def _vec_inputs(rng):
    b = uniform(rng, (N, 3), 0.5, 3.0) * np.where(rng.random((N, 3)) < 0.5, -1, 1)
    return {"a": uniform(rng, (N, 3), -5.0, 5.0), "b": b.astype(np.float32),
            "k": integers(rng, (N, 3), -100, 100), "out": np.zeros((N, 6), np.float32)}  # fmt: skip


def _vec_ref(ins):
    a, b, k = f64(ins["a"]), f64(ins["b"]), ins["k"].astype(np.int64)
    r = a + b - a / 2.0 + 2.0 / b + np.fmod(a, b) - b
    iv = (~k) ^ (k << np.array([1, 2, 3]))
    return {"out": np.concatenate([r, iv.astype(np.float64)], axis=1)}


@wp.kernel
def reversed_ranges(lo: wp.array(dtype=int), hi: wp.array(dtype=int), step: wp.array(dtype=int),
                    first: wp.array(dtype=int), count: wp.array(dtype=int),
                    weighted: wp.array(dtype=int)):  # fmt: skip
    i = wp.tid()
    n = 0
    f = -999
    w = 0
    for j in reversed(range(lo[i], hi[i], step[i])):
        if n == 0:
            f = j
        n += 1
        w += j * n
    first[i] = f
    count[i] = n
    weighted[i] = w


def _rev_inputs(rng):
    lo = integers(rng, N, -10, 10)
    hi = integers(rng, N, -10, 10)
    step = integers(rng, N, 1, 4) * np.where(rng.random(N) < 0.5, -1, 1).astype(np.int32)
    z = np.zeros(N, np.int32)
    return {"lo": lo, "hi": hi, "step": step, "first": z, "count": z.copy(), "weighted": z.copy()}


def _rev_ref(ins):
    first, count, weighted = [], [], []
    for lo, hi, st in zip(ins["lo"].tolist(), ins["hi"].tolist(), ins["step"].tolist()):
        vals = list(reversed(range(lo, hi, st)))
        w = 0
        for k, v in enumerate(vals):
            w += v * (k + 1)
        first.append(vals[0] if vals else -999)
        count.append(len(vals))
        weighted.append(w)
    return {k: np.array(v, np.int32) for k, v in
            (("first", first), ("count", count), ("weighted", weighted))}  # fmt: skip


@wp.kernel
def bit_casts(f: wp.array(dtype=float), i: wp.array(dtype=wp.int32), u: wp.array(dtype=wp.uint32),
              back: wp.array(dtype=float), h: wp.array(dtype=wp.float16),
              hs: wp.array(dtype=wp.int16), bd: wp.array(dtype=int)):  # fmt: skip
    t = wp.tid()
    i[t] = wp.cast(f[t], wp.int32)
    u[t] = wp.cast(f[t], wp.uint32)
    back[t] = wp.cast(i[t] ^ 1, float)
    hs[t] = wp.cast(h[t], wp.int16)
    bd[t] = wp.min(wp.block_dim(), 1)


def _cast_inputs(rng):
    f = uniform(rng, N, -100.0, 100.0)
    f[:4] = [0.0, -0.0, 1.0e30, 1.0]
    h = uniform(rng, N, -10.0, 10.0, np.float16)
    z = np.zeros(N, np.int32)
    return {"f": f, "i": z, "u": z.astype(np.uint32), "back": np.zeros(N, np.float32), "h": h,
            "hs": np.zeros(N, np.int16), "bd": z.copy()}  # fmt: skip


def _cast_ref(ins):
    f = ins["f"]
    i = f.view(np.int32)
    return {"i": i, "u": f.view(np.uint32), "back": f64((i ^ 1).view(np.float32)),
            "hs": ins["h"].view(np.int16), "bd": np.ones(len(f), np.int32)}  # fmt: skip


@wp.kernel
def lower_bound_search(arr: wp.array(dtype=float), q: wp.array(dtype=float),
                       whole: wp.array(dtype=int), part: wp.array(dtype=int)):  # fmt: skip
    i = wp.tid()
    whole[i] = wp.lower_bound(arr, q[i])
    part[i] = wp.lower_bound(arr, 3, 9, q[i])


def _lb_inputs(rng):
    arr = np.sort(integers(rng, 16, 0, 20).astype(np.float32))
    q = integers(rng, N, -2, 23).astype(np.float32) + np.where(rng.random(N) < 0.3, 0.5, 0.0)
    z = np.zeros(N, np.int32)
    return {"arr": arr, "q": q.astype(np.float32), "whole": z, "part": z.copy()}


def _warp_lower_bound(arr, begin, end, v):
    # Warp searches [begin, end - 1]: with no element >= v the answer is end - 1.
    if end <= begin:
        return begin
    return min(begin + int(np.searchsorted(arr[begin:end], v, side="left")), end - 1)


def _lb_ref(ins):
    arr = ins["arr"].tolist()
    qs = ins["q"].tolist()
    return {"whole": np.array([_warp_lower_bound(arr, 0, len(arr), v) for v in qs], np.int32),
            "part": np.array([_warp_lower_bound(arr, 3, 9, v) for v in qs], np.int32)}  # fmt: skip


def _edge_kernel(dtype):
    V3 = wp.types.vector(3, dtype)

    @wp.kernel
    def edge_tri_queries(p: wp.array2d(dtype=V3), closest: wp.array(dtype=V3),
                         hit: wp.array(dtype=int)):  # fmt: skip
        i = wp.tid()
        closest[i] = wp.closest_point_edge_edge(p[i, 0], p[i, 1], p[i, 2], p[i, 3], dtype(1.0e-6))
        hit[i] = wp.intersect_tri_tri(p[i, 0], p[i, 1], p[i, 2], p[i, 3], p[i, 4], p[i, 5])

    return edge_tri_queries


def _edge_inputs(np_dtype):
    def make(rng):
        p = uniform(rng, (N, 6, 3), -1.0, 1.0, np_dtype)
        p[1, 1] = p[1, 0]  # a degenerate first edge
        p[2, 3] = p[2, 2]  # a degenerate second edge
        p[3, 2:4] = p[3, 0:2] + np.array([0.0, 0.5, 0.0], np_dtype)  # parallel edges
        p[4, 3:6] = p[4, 0:3] + np.array([0.1, 0.1, 0.0], np_dtype)  # coplanar, overlapping
        p[5, 3:6] = p[5, 0:3] + np.array([5.0, 0.0, 0.0], np_dtype)  # far apart
        return {"p": p, "closest": np.zeros((N, 3), np_dtype), "hit": np.zeros(N, np.int32)}

    return make


def _clamp01(x):
    return min(max(x, 0.0), 1.0)


def _closest(p1, q1, p2, q2, eps=1e-6):
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e, f = d1 @ d1, d2 @ d2, d2 @ r
    s = t = 0.0
    if a <= eps and e <= eps:
        pass
    elif a <= eps:
        t = _clamp01(f / e)
    elif e <= eps:
        s = _clamp01(-(d1 @ r) / a)
    else:
        c, b = d1 @ r, d1 @ d2
        denom = a * e - b * b
        s0 = _clamp01((b * f - c * e) / denom) if denom > 0 else 0.0
        t0 = (b * s0 + f) / e
        if t0 < 0:
            s = _clamp01(-c / a)
        elif t0 > 1:
            s, t = _clamp01((b - c) / a), 1.0
        else:
            s, t = s0, t0
    return [s, t, np.linalg.norm((p2 + t * d2) - (p1 + s * d1))]


def _tri_hit(v, u):
    ev = [v[1] - v[0], v[2] - v[1], v[0] - v[2]]
    eu = [u[1] - u[0], u[2] - u[1], u[0] - u[2]]
    nv, nu = np.cross(ev[0], ev[1]), np.cross(eu[0], eu[1])
    axes = [nv, nu] + [np.cross(nv, e) for e in ev] + [np.cross(nu, e) for e in eu]
    axes += [np.cross(a, b) for a in ev for b in eu]
    for ax in axes:
        pv, pu = v @ ax, u @ ax
        if pv.max() < pu.min() or pu.max() < pv.min():
            return 0
    return 1


def _edge_ref(ins):
    p = f64(ins["p"])
    closest = [_closest(*row[:4]) for row in p]
    hit = [_tri_hit(row[:3], row[3:]) for row in p]
    return {"closest": np.array(closest), "hit": np.array(hit, np.int32)}


def _cases() -> list[Case]:
    cases = []
    for name, dtype, np_dtype, req in FLOAT_TYPES:
        cases.append(Case(f"operator_builtins_{name}", _float_ops_kernel(dtype), N,
                          _float_ops_inputs(np_dtype), _float_ops_ref, ("out",), requires=req))  # fmt: skip
        cases.append(Case(f"edge_tri_queries_{name}", _edge_kernel(dtype), N,
                          _edge_inputs(np_dtype), _edge_ref, ("closest", "hit"), requires=req,
                          tol=(1e-4, 1e-5) if name == "f32" else None))  # fmt: skip
    for name, dtype, np_dtype, req in INT_TYPES:
        cases.append(Case(f"operator_builtins_{name}", _int_ops_kernel(dtype), N,
                          _int_ops_inputs(np_dtype), _int_ops_ref, ("out",), requires=req))  # fmt: skip
    cases += [
        Case("operator_builtins_vec3", vector_operator_builtins, N, _vec_inputs, _vec_ref, ("out",),
             tol=(1e-5, 1e-5)),
        Case("reversed_ranges", reversed_ranges, N, _rev_inputs, _rev_ref,
             ("first", "count", "weighted")),
        Case("bit_casts", bit_casts, N, _cast_inputs, _cast_ref, ("i", "u", "back", "hs", "bd"),
             requires=("int16",)),
        Case("lower_bound_search", lower_bound_search, N, _lb_inputs, _lb_ref, ("whole", "part")),
    ]  # fmt: skip
    return cases


CASES = _cases()
