"""Reference numeric semantics shared by the interpreter rules and the folder.

These helpers define, once, what integer overflow, division by zero, casts and
rounding do in kdsl. Every backend must match them (the conformance suite checks).

- Integers wrap (two's complement). ``a / 0``, ``a // 0`` and ``a % 0`` give 0.
- Integer ``/`` truncates toward zero (C); ``//`` floors (Python); ``%`` takes the
  sign of the dividend (C ``%``, Warp's ``mod``).
- Float to integer casts truncate toward zero and saturate; NaN gives 0 (PTX
  ``cvt.rzi.sat``, LLVM ``fptosi.sat``).
- Shifts by the bit width or more give 0 (``>>`` of a negative signed value: -1).
- ``min``/``max`` of floats return the other operand when one is NaN and order
  -0.0 below +0.0 (IEEE 754-2019 ``minimumNumber``/``maximumNumber``), so both are
  commutative, bit for bit.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from kdsl.ir.types import ScalarType, Type, elem_type, value_shape


def np_value(value: Any, t: Type) -> Any:
    """``value`` as the interpreter's representation of type ``t``."""
    et = elem_type(t)
    if isinstance(t, ScalarType):
        return cast_scalar_array(np.asarray(value), et)[()]
    return cast_scalar_array(np.asarray(value), et).reshape(value_shape(t))


def unwrap(arr: np.ndarray) -> Any:
    """A 0-d array becomes a NumPy scalar; anything else stays an array."""
    return arr[()] if arr.ndim == 0 else arr


def cast_scalar_array(x: np.ndarray, to: ScalarType) -> np.ndarray:
    """Elementwise cast with kdsl's rules (wrap, saturate, NaN to 0, bool = != 0)."""
    x = np.asarray(x)
    if to.is_bool:
        return x != 0
    if to.is_float:
        with np.errstate(all="ignore"):
            return x.astype(to.np_dtype)
    info = np.iinfo(to.np_dtype)
    if x.dtype.kind == "f":
        with np.errstate(all="ignore"):
            t = np.trunc(np.where(np.isnan(x), 0.0, x.astype(np.float64)))
            # float(info.max) of a 64-bit type rounds up past the range, so compare
            # with >= and pick the exact bound.
            inner = np.clip(t, float(info.min), float(info.max)).astype(
                to.np_dtype, casting="unsafe"
            )
            return np.where(
                t >= float(info.max), info.max, np.where(t <= float(info.min), info.min, inner)
            ).astype(to.np_dtype)
    if x.dtype.kind == "b":
        return x.astype(to.np_dtype)
    # Integer to integer: wrap through the unsigned width.
    return x.astype(np.int64 if x.dtype.kind == "i" else np.uint64).astype(
        to.np_dtype, casting="unsafe"
    )


def _total(fn: Callable[[np.ndarray, np.ndarray], np.ndarray]):
    """Integer ``fn(a, b)`` made total: it never sees a zero ``b`` and gives 0 there."""

    def apply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        zero = b == 0
        safe_b = np.where(zero, 1, b).astype(b.dtype)
        with np.errstate(all="ignore"):
            out = fn(a, safe_b)
        return np.where(zero, 0, out).astype(a.dtype)

    return apply


def _trunc_div(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    q = np.floor_divide(a, b)
    if a.dtype.kind == "i":
        fix = (a - q * b != 0) & ((a < 0) != (b < 0))
        q = np.where(fix, q + 1, q).astype(a.dtype)
    return q


#: C-style integer division (truncate toward zero); division by zero gives 0.
int_div = _total(_trunc_div)
#: Python-style floor division for integers; division by zero gives 0.
int_floordiv = _total(np.floor_divide)
#: C-style remainder (sign of the dividend); modulo zero gives 0.
int_mod = _total(np.fmod)


def shift_left(a: np.ndarray, s: np.ndarray) -> np.ndarray:
    bits = a.dtype.itemsize * 8
    big = (s < 0) | (s >= bits)
    safe = np.where(big, 0, s).astype(a.dtype)
    return np.where(big, 0, np.left_shift(a, safe)).astype(a.dtype)


def shift_right(a: np.ndarray, s: np.ndarray) -> np.ndarray:
    bits = a.dtype.itemsize * 8
    big = (s < 0) | (s >= bits)
    safe = np.where(big, 0, s).astype(a.dtype)
    fill = np.where(a < 0, -1, 0) if a.dtype.kind == "i" else 0
    return np.where(big, fill, np.right_shift(a, safe)).astype(a.dtype)


def round_half_away(x: np.ndarray) -> np.ndarray:
    """C ``round``: halves go away from zero (exact for every float)."""
    t = np.trunc(x)
    frac = np.abs(x - t)
    return np.where(frac >= 0.5, t + np.sign(x), t).astype(x.dtype)


def _signed_zero_fix(
    a: np.ndarray, b: np.ndarray, r: np.ndarray, negative: np.ndarray
) -> np.ndarray:
    both_zero = (a == 0) & (b == 0)
    zero = np.where(negative, -0.0, 0.0).astype(r.dtype)
    return np.where(both_zero, zero, r).astype(r.dtype)


def float_min(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Elementwise min: NaN loses, -0.0 < +0.0; integers compare plainly."""
    a, b = np.asarray(a), np.asarray(b)
    r = np.asarray(np.fmin(a, b))
    if r.dtype.kind != "f":
        return r
    return _signed_zero_fix(a, b, r, np.signbit(a) | np.signbit(b))


def float_max(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Elementwise max: NaN loses, +0.0 > -0.0; integers compare plainly."""
    a, b = np.asarray(a), np.asarray(b)
    r = np.asarray(np.fmax(a, b))
    if r.dtype.kind != "f":
        return r
    return _signed_zero_fix(a, b, r, np.signbit(a) & np.signbit(b))
