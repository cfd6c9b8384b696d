"""The ``arith`` dialect: constants, arithmetic, comparisons, logic, casts, select.

Binary arithmetic works on two values of the same type (scalar, vector or
matrix, elementwise) and, for ``mul`` and ``div``, on a scalar and a composite of
that scalar type. Type rules raise ``TypeError`` with a user-facing message; the
frontend attaches the source location.

Untyped Python literals combine with Python's own operators (``literal_folder``):
``2 ** 10`` is the int 1024 and ``1.5 * 2`` the float 3.0 before either takes a
type. Integer ``/`` and ``//``, ``%`` and shifts of literals are not folded that
way: the literals take their types and the op keeps C's semantics (``7 / 2`` is 3).
"""

from __future__ import annotations

import operator
from collections.abc import Sequence
from typing import Any

import numpy as np

from kdsl.ir import semantics as sem
from kdsl.ir.catalog import (
    CATALOG,
    COMMUTATIVE,
    CONSTANT_LIKE,
    INVOLUTION,
    PURE,
    SPECULATABLE,
    OpDef,
)
from kdsl.ir.types import BOOL, MatrixType, ScalarType, Type, VectorType, elem_type, with_elem

_PURE = frozenset({PURE, SPECULATABLE})
_PURE_COMM = frozenset({PURE, SPECULATABLE, COMMUTATIVE})

_VERBS = {
    "add": "add", "sub": "subtract", "mul": "multiply", "div": "divide",
    "floordiv": "floor-divide", "mod": "take the remainder of", "pow": "raise",
    "and": "combine with 'and'", "or": "combine with 'or'", "xor": "xor",
    "shl": "shift", "shr": "shift", "min": "take the min of", "max": "take the max of",
}  # fmt: skip


def is_numeric(t: Type) -> bool:
    """Scalars (not bool), vectors and matrices."""
    if isinstance(t, ScalarType):
        return not t.is_bool
    return isinstance(t, VectorType | MatrixType)


def _binary_rule(
    kind: str,
    allow_scaling: bool = False,
    int_only: bool = False,
    float_only: bool = False,
    allow_bool: bool = False,
):
    def rule(ts: Sequence[Type], attrs: dict[str, Any]) -> list[Type]:
        a, b = ts
        verb = _VERBS.get(kind, kind)
        if a == b:
            ok = is_numeric(a) or (allow_bool and a == BOOL)
            if not ok:
                raise TypeError(f"cannot {verb} values of type {a}")
            et = elem_type(a)
            if int_only and not (et.is_int or (allow_bool and et.is_bool)):
                raise TypeError(f"cannot {verb} {a} values: integers are required")
            if float_only and not et.is_float:
                raise TypeError(f"cannot {verb} {a} values: floats are required")
            return [a]
        if allow_scaling:
            if isinstance(a, ScalarType) and isinstance(b, VectorType | MatrixType) and b.elem == a:
                return [b]
            if isinstance(b, ScalarType) and isinstance(a, VectorType | MatrixType) and a.elem == b:
                return [a]
        raise TypeError(
            f"cannot {verb} {a} and {b}: operands must have the same type"
            + (" (or be a scalar and a vector/matrix of it)" if allow_scaling else "")
            + "; use an explicit cast such as float32(x)"
        )

    return rule


def _elementwise(fn):
    """Lift a NumPy function on arrays to an interpreter rule on kdsl values."""

    def interp(ctx, op, a, b):
        ra = np.asarray(a)
        rb = np.asarray(b)
        with np.errstate(all="ignore"):
            out = fn(ra, rb)
        return sem.unwrap(np.asarray(out).astype(ra.dtype if ra.ndim >= rb.ndim else rb.dtype))

    return interp


def _div(a, b):
    if a.dtype.kind in "iu":
        a, b = np.broadcast_arrays(a, b)
        return sem.int_div(a, b.astype(a.dtype))
    return np.true_divide(a, b).astype(a.dtype)


def _floordiv(a, b):
    if a.dtype.kind in "iu":
        a, b = np.broadcast_arrays(a, b)
        return sem.int_floordiv(a, b.astype(a.dtype))
    return np.floor(np.true_divide(a, b)).astype(a.dtype)


def _mod(a, b):
    if a.dtype.kind in "iu":
        a, b = np.broadcast_arrays(a, b)
        return sem.int_mod(a, b.astype(a.dtype))
    return np.fmod(a, b)


def _literal(fn):
    """A literal folder applying the Python operator ``fn``."""
    return lambda attrs, a, b: fn(a, b)


def _literal_div(attrs, a, b):
    # Only true division with a float: int / int keeps C's integer division.
    if (isinstance(a, float) or isinstance(b, float)) and b != 0:
        return a / b
    return None


def _literal_pow(attrs, a, b):
    return None if b < 0 else a**b  # 2 ** -1 is typed (and refused for integers)


# (name, interpreter function, traits, type-rule options, literal folder, example)
_BINARY = [
    ("add", np.add, _PURE_COMM, dict(), _literal(operator.add), "%2 = arith.add %0, %1 : f32"),
    ("sub", np.subtract, _PURE, dict(), _literal(operator.sub), "%2 = arith.sub %0, %1 : vec<3, f32>"),
    ("mul", np.multiply, _PURE_COMM, dict(allow_scaling=True), _literal(operator.mul), "%2 = arith.mul %0, %1 : vec<3, f32>"),
    ("div", _div, _PURE, dict(allow_scaling=True), _literal_div, "%2 = arith.div %0, %1 : i32"),
    ("floordiv", _floordiv, _PURE, dict(), None, "%2 = arith.floordiv %0, %1 : i32"),
    ("mod", _mod, _PURE, dict(), None, "%2 = arith.mod %0, %1 : i32"),
    ("pow", np.power, _PURE, dict(float_only=True), _literal_pow, "%2 = arith.pow %0, %1 : f32"),
    ("min", sem.float_min, _PURE_COMM, dict(), None, "%2 = arith.min %0, %1 : f32"),
    ("max", sem.float_max, _PURE_COMM, dict(), None, "%2 = arith.max %0, %1 : f32"),
    ("and", np.bitwise_and, _PURE_COMM, dict(int_only=True, allow_bool=True), _literal(operator.and_), "%2 = arith.and %0, %1 : bool"),
    ("or", np.bitwise_or, _PURE_COMM, dict(int_only=True, allow_bool=True), _literal(operator.or_), "%2 = arith.or %0, %1 : bool"),
    ("xor", np.bitwise_xor, _PURE_COMM, dict(int_only=True, allow_bool=True), _literal(operator.xor), "%2 = arith.xor %0, %1 : i32"),
    ("shl", sem.shift_left, _PURE, dict(int_only=True), None, "%2 = arith.shl %0, %1 : i32"),
    ("shr", sem.shift_right, _PURE, dict(int_only=True), None, "%2 = arith.shr %0, %1 : i32"),
]  # fmt: skip

_BINARY_DOCS = {
    "add": "Sum of two values of one type (elementwise for vectors and matrices).",
    "sub": "Difference of two values of one type.",
    "mul": "Product: elementwise for equal types, or a scalar times a vector/matrix.",
    "div": "Quotient. Integers truncate toward zero; division by zero gives 0.",
    "floordiv": "Floor division (Python ``//``). Integer division by zero gives 0.",
    "mod": "Remainder with the sign of the dividend (C ``%``/``fmod``); ``x % 0`` is 0.",
    "pow": "``a`` raised to ``b`` (floats only).",
    "min": "Smaller of two values; a NaN operand yields the other; -0.0 < +0.0.",
    "max": "Larger of two values; a NaN operand yields the other; +0.0 > -0.0.",
    "and": "Logical and (bool) or bitwise and (integers).",
    "or": "Logical or (bool) or bitwise or (integers).",
    "xor": "Logical xor (bool) or bitwise xor (integers).",
    "shl": "Shift left; a shift by the bit width or more gives 0.",
    "shr": "Shift right (arithmetic for signed); by the width or more gives 0 or -1.",
}

#: The binary ops by short name (``"add"`` -> ``arith.add``).
BINARY_OPS: dict[str, OpDef] = {}
for _name, _fn, _traits, _opts, _literal_fn, _example in _BINARY:
    BINARY_OPS[_name] = CATALOG.define(
        f"arith.{_name}",
        _BINARY_DOCS[_name],
        traits=_traits,
        type_rule=_binary_rule(_name, **_opts),
        interp=_elementwise(_fn),
        literal_folder=_literal_fn,
        example=_example,
        group="arithmetic",
    )
ADD, SUB, MUL = BINARY_OPS["add"], BINARY_OPS["sub"], BINARY_OPS["mul"]
AND, OR = BINARY_OPS["and"], BINARY_OPS["or"]


def _constant_interp(ctx, op):
    return sem.np_value(op.attrs["value"], op.results[0].type)


def _constant_verify(op) -> None:
    t = op.results[0].type
    if not isinstance(t, ScalarType):
        raise TypeError(f"arith.constant must have a scalar type, not {t}")


CONSTANT = CATALOG.define(
    "arith.constant",
    "A scalar constant. ``value`` holds it exactly (floats at full precision).",
    traits=_PURE | {CONSTANT_LIKE},
    verifier=_constant_verify,
    interp=_constant_interp,
    required_attrs=("value",),
    example="%0 = arith.constant {value = 1.5} : f32",
    group="arithmetic",
)


def _unary_same(kind: str, pred, what: str):
    def rule(ts: Sequence[Type], attrs: dict[str, Any]) -> list[Type]:
        (a,) = ts
        if not pred(a):
            raise TypeError(f"cannot {kind} a value of type {a}: {what} required")
        return [a]

    return rule


def _neg_interp(ctx, op, a):
    with np.errstate(all="ignore"):
        return sem.unwrap(np.negative(np.asarray(a)))


def _not_interp(ctx, op, a):
    return np.logical_not(a)


def _bitnot_interp(ctx, op, a):
    return sem.unwrap(np.invert(np.asarray(a)))


NEG = CATALOG.define(
    "arith.neg", "Negation (integers wrap).", traits=_PURE | {INVOLUTION},
    type_rule=_unary_same("negate", lambda t: is_numeric(t), "a number, vector or matrix"),
    interp=_neg_interp, literal_folder=lambda attrs, a: -a,
    example="%1 = arith.neg %0 : f32", group="arithmetic",
)  # fmt: skip
NOT = CATALOG.define(
    "arith.not", "Logical not of a bool.", traits=_PURE | {INVOLUTION},
    type_rule=_unary_same("apply 'not' to", lambda t: t == BOOL, "a bool"),
    interp=_not_interp, literal_folder=lambda attrs, a: not a,
    example="%1 = arith.not %0 : bool", group="arithmetic",
)  # fmt: skip
CATALOG.define(
    "arith.bitnot", "Bitwise complement of an integer.", traits=_PURE,
    type_rule=_unary_same("invert", lambda t: isinstance(t, ScalarType) and t.is_int, "an integer"),
    interp=_bitnot_interp, example="%1 = arith.bitnot %0 : i32", group="arithmetic",
)  # fmt: skip

CMP_PREDICATES = ("eq", "ne", "lt", "le", "gt", "ge")


def _cmp_rule(ts: Sequence[Type], attrs: dict[str, Any]) -> list[Type]:
    a, b = ts
    pred = attrs.get("pred")
    if pred not in CMP_PREDICATES:
        raise TypeError(f"unknown comparison predicate {pred!r}")
    if a != b:
        raise TypeError(f"cannot compare {a} and {b}: operands must have the same type")
    if not isinstance(a, ScalarType) and pred not in ("eq", "ne"):
        raise TypeError(f"cannot order values of type {a}: only == and != compare them")
    if not isinstance(a, ScalarType | VectorType | MatrixType):
        raise TypeError(f"cannot compare values of type {a}")
    return [BOOL]


_CMP_FNS = {
    "eq": np.equal, "ne": np.not_equal, "lt": np.less,
    "le": np.less_equal, "gt": np.greater, "ge": np.greater_equal,
}  # fmt: skip
_CMP_LITERAL = {
    "eq": operator.eq, "ne": operator.ne, "lt": operator.lt,
    "le": operator.le, "gt": operator.gt, "ge": operator.ge,
}  # fmt: skip


def _cmp_interp(ctx, op, a, b):
    pred = op.attrs["pred"]
    r = _CMP_FNS[pred](np.asarray(a), np.asarray(b))
    if r.ndim == 0:
        return np.bool_(r)
    # Whole-value equality for vectors and matrices.
    return np.bool_(r.all()) if pred == "eq" else np.bool_(r.any())


CMP = CATALOG.define(
    "arith.cmp",
    "Comparison with predicate ``pred`` (eq, ne, lt, le, gt, ge) giving a bool. "
    "Vectors and matrices compare whole with eq/ne. Ordered float comparisons with "
    "NaN are false; ne with NaN is true.",
    traits=_PURE,
    type_rule=_cmp_rule,
    interp=_cmp_interp,
    literal_folder=lambda attrs, a, b: _CMP_LITERAL[attrs["pred"]](a, b),
    required_attrs=("pred",),
    example='%2 = arith.cmp %0, %1 {pred = "lt"} : bool',
    group="arithmetic",
)


def _cast_verify(op) -> None:
    src = op.operands[0].type
    dst = op.results[0].type
    try:
        same_shape = with_elem(src, elem_type(dst)) == dst
    except TypeError:
        same_shape = False
    if not same_shape:
        raise TypeError(f"cannot cast {src} to {dst}")


def _cast_interp(ctx, op, a):
    dst = op.results[0].type
    return sem.unwrap(sem.cast_scalar_array(np.asarray(a), elem_type(dst)))


CAST = CATALOG.define(
    "arith.cast",
    "Conversion to the result type (same shape, other element type). Float to "
    "integer truncates toward zero and saturates, NaN gives 0; integers wrap; "
    "to bool is ``!= 0``.",
    traits=_PURE,
    verifier=_cast_verify,
    interp=_cast_interp,
    example="%1 = arith.cast %0 : i32",
    group="arithmetic",
)


def _bitcast_verify(op) -> None:
    src = op.operands[0].type
    dst = op.results[0].type
    ok = all(isinstance(t, ScalarType) and not t.is_bool for t in (src, dst))
    if not ok or src.bits != dst.bits:
        raise TypeError(f"cannot reinterpret the bits of a {src} as a {dst}: both must be "
                        "numeric scalars of one width")  # fmt: skip


def _bitcast_interp(ctx, op, a):
    src, dst = op.operands[0].type, op.results[0].type
    return np.asarray(a, dtype=src.np_dtype).view(dst.np_dtype)[()]


BITCAST = CATALOG.define(
    "arith.bitcast",
    "The bits of a numeric scalar reinterpreted as another numeric scalar type of the "
    "same width (``float32`` 1.0 as ``int32`` is ``0x3f800000``).",
    traits=_PURE,
    verifier=_bitcast_verify,
    interp=_bitcast_interp,
    example="%1 = arith.bitcast %0 : i32",
    group="arithmetic",
)


def _select_rule(ts: Sequence[Type], attrs: dict[str, Any]) -> list[Type]:
    c, a, b = ts
    if c != BOOL:
        raise TypeError(f"the condition of a select must be bool, not {c}")
    if a != b:
        raise TypeError(f"both choices of a select must have one type, got {a} and {b}")
    return [a]


def _select_interp(ctx, op, c, a, b):
    return a if c else b


SELECT = CATALOG.define(
    "arith.select",
    "``a`` if ``cond`` else ``b``; both are evaluated.",
    traits=_PURE,
    type_rule=_select_rule,
    interp=_select_interp,
    example="%3 = arith.select %0, %1, %2 : f32",
    group="arithmetic",
)
