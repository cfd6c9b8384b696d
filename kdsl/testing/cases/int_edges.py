"""Conformance cases for kdsl's defined integer results (helper of ``atomics_print``).

Division and remainder by zero give 0, ``MIN / -1`` wraps to ``MIN``, shifts by a
count outside ``[0, bits)`` give 0 (``>>`` of a negative value: -1), and float to
integer casts truncate toward zero, saturate at the type's bounds and send NaN to 0
(see ``docs/semantics.md``). References are plain Python integer arithmetic,
independent of ``kdsl.ir.semantics``.
"""

import numpy as np

import kdsl as wp
from kdsl.testing.case import Case
from kdsl.testing.cases.dtype_rows import FLOAT_TYPES, INT_TYPES, SMALL_INT_TYPES
from kdsl.testing.cases.dtype_rows import wrap as _wrap


def _divmod_kernel(dtype):
    @wp.kernel
    def int_divmod(a: wp.array(dtype=dtype), b: wp.array(dtype=dtype), q: wp.array(dtype=dtype),
                   f: wp.array(dtype=dtype), r: wp.array(dtype=dtype)):  # fmt: skip
        i = wp.tid()
        q[i] = a[i] / b[i]
        f[i] = a[i] // b[i]
        r[i] = a[i] % b[i]

    return int_divmod


def _divmod_values(np_dtype) -> tuple[list[int], list[int]]:
    info = np.iinfo(np_dtype)
    lo, hi = int(info.min), int(info.max)
    a = [7, 7, 0, lo, lo, hi, hi, 5, lo, hi, 1, 3]
    b = [2, 0, 0, 0, 1, 1, 0, 7, 2, 3, hi, hi]
    if lo < 0:  # MIN / -1 overflows: it wraps to MIN, and MIN % -1 is 0
        a += [-7, -7, 7, lo, lo, -1, -5, -6, hi]
        b += [2, -2, -2, -1, -2, lo, 0, -3, lo]
    return a, b


def _divmod_inputs(np_dtype):
    a, b = _divmod_values(np_dtype)
    n = len(a)

    def make(rng):
        return {"a": np.array(a, np_dtype), "b": np.array(b, np_dtype),
                "q": np.zeros(n, np_dtype), "f": np.zeros(n, np_dtype),
                "r": np.zeros(n, np_dtype)}  # fmt: skip

    return make, n


def _divmod_ref(ins):
    dt = ins["a"].dtype
    q, f, r = [], [], []
    for x, y in zip(ins["a"].tolist(), ins["b"].tolist()):
        if y == 0:
            q.append(0), f.append(0), r.append(0)
            continue
        t = abs(x) // abs(y) * (1 if (x < 0) == (y < 0) else -1)  # toward zero
        q.append(t)
        f.append(x // y)
        r.append(x - t * y)
    return {"q": _wrap(q, dt), "f": _wrap(f, dt), "r": _wrap(r, dt)}


def _shift_kernel(dtype):
    @wp.kernel
    def int_shifts(a: wp.array(dtype=dtype), s: wp.array(dtype=dtype), left: wp.array(dtype=dtype),
                   right: wp.array(dtype=dtype)):  # fmt: skip
        i = wp.tid()
        left[i] = a[i] << s[i]
        right[i] = a[i] >> s[i]

    return int_shifts


def _shift_inputs(np_dtype):
    info = np.iinfo(np_dtype)
    bits = info.bits
    a = [1, 3, int(info.max), int(info.min), 5, 1, 12345 % int(info.max), 2, 1]
    s = [0, bits - 1, 1, bits - 1, bits, bits + 1, 2 * bits, 3, 255]
    if info.min < 0:  # negative values and negative shift counts
        a += [-8, -8, -1, -8, 8]
        s += [1, bits, bits - 1, -1, -3]
    n = len(a)

    def make(rng):
        return {"a": _wrap(a, np_dtype), "s": _wrap(s, np_dtype), "left": np.zeros(n, np_dtype),
                "right": np.zeros(n, np_dtype)}  # fmt: skip

    return make, n


def _shift_ref(ins):
    dt = ins["a"].dtype
    bits = np.iinfo(dt).bits
    left, right = [], []
    for x, s in zip(ins["a"].tolist(), ins["s"].tolist()):
        if s < 0 or s >= bits:  # out of range: 0, or all sign bits for >>
            left.append(0)
            right.append(-1 if x < 0 else 0)
        else:
            left.append(x << s)
            right.append(x >> s)  # Python's >> is arithmetic, as for signed C types
    return {"left": _wrap(left, dt), "right": _wrap(right, dt)}


def _cast_kernel(src, dst):
    @wp.kernel
    def float_to_int(x: wp.array(dtype=src), out: wp.array(dtype=dst)):
        i = wp.tid()
        out[i] = dst(x[i])

    return float_to_int


_CAST_COUNT = 22


def _cast_inputs(np_src, np_dst):
    def make(rng):
        info = np.iinfo(np_dst)
        x = [np.nan, np.inf, -np.inf, -0.0, 0.0, 0.5, -0.5, 0.99, -0.99, 2.5, -2.5, 1e30, -1e30,
             float(info.max) + 1000.0, float(info.min) - 1000.0, float(info.max) / 2,
             float(info.min) / 2, 1e-40, 200.7, -129.2, 65535.9, -32768.9]  # fmt: skip
        xs = np.array(x, np.float64).astype(np_src)
        return {"x": xs, "out": np.zeros(len(xs), np_dst)}

    return make


def _cast_ref(ins):
    dt = ins["out"].dtype
    info = np.iinfo(dt)
    out = []
    for v in ins["x"].tolist():  # exact Python floats of the source values
        if v != v:
            out.append(0)
        elif v >= int(info.max):
            out.append(int(info.max))
        elif v <= int(info.min):
            out.append(int(info.min))
        else:
            out.append(int(v))  # truncates toward zero
    return {"out": np.array(out, dt)}


_CAST_DSTS = (*SMALL_INT_TYPES, *INT_TYPES)


def int_cases() -> list[Case]:
    """Division, remainder, shift and float-to-integer cast edge cases, per integer type."""
    cases = []
    for name, dtype, np_dtype, req in INT_TYPES + SMALL_INT_TYPES:
        make, n = _divmod_inputs(np_dtype)
        cases.append(Case(f"int_div_mod_edges_{name}", _divmod_kernel(dtype), n, make,
                          _divmod_ref, ("q", "f", "r"), requires=req))  # fmt: skip
        make, n = _shift_inputs(np_dtype)
        cases.append(Case(f"int_shift_edges_{name}", _shift_kernel(dtype), n, make, _shift_ref,
                          ("left", "right"), requires=req))  # fmt: skip
    for sname, src, np_src, sreq in FLOAT_TYPES:
        for dname, dst, np_dst, dreq in _CAST_DSTS:
            cases.append(Case(f"cast_{sname}_to_{dname}_edges", _cast_kernel(src, dst), _CAST_COUNT,
                              _cast_inputs(np_src, np_dst), _cast_ref, ("out",),
                              requires=(*sreq, *dreq)))  # fmt: skip
    return cases
