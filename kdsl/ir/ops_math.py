"""The ``math`` dialect: elementwise math intrinsics a backend maps to its libm.

Each op takes a scalar, vector or matrix and works elementwise. Float-only ops
reject integers (cast first); ``abs``, ``sign`` work on integers too. Predicates
(``isnan``, ``isinf``, ``isfinite``) give a bool for a scalar.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from kdsl.ir import semantics as sem
from kdsl.ir.catalog import CATALOG, PURE, SPECULATABLE, InterpRule, TypeRule
from kdsl.ir.ops_arith import is_numeric
from kdsl.ir.types import BOOL, I32, ScalarType, Type, elem_type

_PURE = frozenset({PURE, SPECULATABLE})

_erf = np.vectorize(math.erf, otypes=[np.float64])
_erfc = np.vectorize(math.erfc, otypes=[np.float64])


def _sign(x: np.ndarray) -> np.ndarray:
    # Warp's sign: -1 for negative, +1 otherwise (sign(0) = 1).
    return np.where(x < 0, -1, 1).astype(x.dtype)


def _via_f64(fn):
    def apply(x: np.ndarray) -> np.ndarray:
        return fn(x.astype(np.float64)).astype(x.dtype)

    return apply


#: name -> (NumPy implementation, floats only?, doc)
UNARY_MATH: dict[str, tuple[Any, bool, str]] = {
    "sqrt": (np.sqrt, True, "Square root; NaN below zero."),
    "cbrt": (np.cbrt, True, "Cube root."),
    "exp": (np.exp, True, "e raised to x."),
    "exp2": (np.exp2, True, "2 raised to x."),
    "log": (np.log, True, "Natural logarithm."),
    "log2": (np.log2, True, "Base-2 logarithm."),
    "log10": (np.log10, True, "Base-10 logarithm."),
    "sin": (np.sin, True, "Sine (radians)."),
    "cos": (np.cos, True, "Cosine (radians)."),
    "tan": (np.tan, True, "Tangent (radians)."),
    "asin": (np.arcsin, True, "Arc sine; NaN outside [-1, 1]."),
    "acos": (np.arccos, True, "Arc cosine; NaN outside [-1, 1]."),
    "atan": (np.arctan, True, "Arc tangent."),
    "sinh": (np.sinh, True, "Hyperbolic sine."),
    "cosh": (np.cosh, True, "Hyperbolic cosine."),
    "tanh": (np.tanh, True, "Hyperbolic tangent."),
    "erf": (_via_f64(_erf), True, "Error function."),
    "erfc": (_via_f64(_erfc), True, "Complementary error function."),
    "floor": (np.floor, True, "Largest integer value not above x."),
    "ceil": (np.ceil, True, "Smallest integer value not below x."),
    "trunc": (np.trunc, True, "x rounded toward zero."),
    "round": (sem.round_half_away, True, "x rounded to nearest, halves away from zero."),
    "rint": (np.rint, True, "x rounded to nearest, halves to even."),
    "abs": (np.abs, False, "Absolute value (integers wrap at the minimum)."),
    "sign": (_sign, False, "-1 for negative x, else 1 (so sign(0) is 1, as in Warp)."),
}

PREDICATES: dict[str, tuple[Any, str]] = {
    "isnan": (np.isnan, "True if x is NaN."),
    "isinf": (np.isinf, "True if x is +inf or -inf."),
    "isfinite": (np.isfinite, "True if x is neither NaN nor infinite."),
}

BINARY_MATH: dict[str, tuple[Any, str]] = {
    "atan2": (np.arctan2, "Arc tangent of y/x using both signs: ``atan2(y, x)``."),
    "copysign": (np.copysign, "|a| with the sign of b."),
}


def _define(name: str, doc: str, rule: TypeRule, interp: InterpRule, example: str) -> None:
    """Define ``math.<name>``, pure and speculatable like every op here.

    ``example`` is the text-form example with ``{}`` where the op's name goes.
    """
    CATALOG.define(
        f"math.{name}", doc, traits=_PURE, type_rule=rule, interp=interp,
        example=example.format(f"math.{name}"), group="math",
    )  # fmt: skip


def _unary_rule(name: str, float_only: bool):
    def rule(ts: Sequence[Type], attrs: dict[str, Any]) -> list[Type]:
        (a,) = ts
        if not is_numeric(a):
            raise TypeError(f"{name}() needs a number, vector or matrix, not {a}")
        if float_only and not elem_type(a).is_float:
            raise TypeError(f"{name}() needs a float argument, not {a}; cast it first")
        return [a]

    return rule


def _unary_interp(fn):
    def interp(ctx, op, a):
        with np.errstate(all="ignore"):
            return sem.unwrap(np.asarray(fn(np.asarray(a))).astype(np.asarray(a).dtype))

    return interp


for _name, (_fn, _float_only, _doc) in UNARY_MATH.items():
    _define(_name, _doc, _unary_rule(_name, _float_only), _unary_interp(_fn), "%1 = {} %0 : f32")


def _pred_rule(name: str):
    def rule(ts: Sequence[Type], attrs: dict[str, Any]) -> list[Type]:
        (a,) = ts
        if not (isinstance(a, ScalarType) and a.is_float):
            raise TypeError(f"{name}() needs a float scalar, not {a}")
        return [BOOL]

    return rule


def _pred_interp(fn):
    def interp(ctx, op, a):
        return np.bool_(fn(a))

    return interp


for _name, (_fn, _doc) in PREDICATES.items():
    _define(_name, _doc, _pred_rule(_name), _pred_interp(_fn), "%1 = {} %0 : bool")


def _binary_rule(name: str):
    def rule(ts: Sequence[Type], attrs: dict[str, Any]) -> list[Type]:
        a, b = ts
        if a != b:
            raise TypeError(f"{name}() needs two arguments of one type, got {a} and {b}")
        if not is_numeric(a) or not elem_type(a).is_float:
            raise TypeError(f"{name}() needs float arguments, not {a}")
        return [a]

    return rule


def _binary_interp(fn):
    def interp(ctx, op, a, b):
        with np.errstate(all="ignore"):
            return sem.unwrap(
                np.asarray(fn(np.asarray(a), np.asarray(b))).astype(np.asarray(a).dtype)
            )

    return interp


for _name, (_fn, _doc) in BINARY_MATH.items():
    _define(_name, _doc, _binary_rule(_name), _binary_interp(_fn), "%2 = {} %0, %1 : f32")


def _bit_count_rule(ts: Sequence[Type], attrs: dict[str, Any]) -> list[Type]:
    (a,) = ts
    if not (isinstance(a, ScalarType) and a.is_int):
        raise TypeError(f"bit_count() needs an integer scalar, not {a}")
    return [I32]


def _bit_count_interp(ctx, op, a):
    # Count the bits of the two's-complement pattern (byte view; numpy >= 1.24 has no
    # bitwise_count).
    return np.int32(np.unpackbits(np.ascontiguousarray(a).reshape(1).view(np.uint8)).sum())


_define(
    "bit_count",
    "Number of set bits in an integer's two's-complement representation (an i32).",
    _bit_count_rule,
    _bit_count_interp,
    "%1 = {} %0 : i32",
)
