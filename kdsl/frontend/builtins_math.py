"""Scalar math builtins composed from catalog ops: ``clamp``, ``lerp``, ``smoothstep``,
``step``, ``nonzero``, ``frac``, ``degrees``, ``radians``, ``bit_count``.

Each lowers to a few ``arith``/``math`` ops (no op of its own, so every backend and
autodiff get them for free). Float semantics (see ``docs/semantics.md``): ``clamp``
gives NaN for a NaN ``x`` (Warp gives the lower bound); the others follow Warp.
The helpers ``components``/``assemble``/``map_scalar`` work on any scalar, vector or
matrix value and are shared with ``builtins_linalg`` and ``builtins_core``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from kdsl.errors import KdslTypeError
from kdsl.frontend.builtins_base import BuiltinTable, float_default, unified
from kdsl.frontend.values import is_weak
from kdsl.ir import Value
from kdsl.ir.types import I32, MatrixType, ScalarType, Type, VectorType, elem_type

TABLE = BuiltinTable(__name__)


def components(em, v: Value, node) -> list[Value]:
    """The scalar components of ``v`` (itself for a scalar; matrices row-major)."""
    t = v.type
    if isinstance(t, ScalarType):
        return [v]
    if isinstance(t, MatrixType):
        return [em.emit("vec.extract", v, em.const(i, I32, node), em.const(j, I32, node),
                        node=node) for i in range(t.rows) for j in range(t.cols)]  # fmt: skip
    return [em.emit("vec.extract", v, em.const(i, I32, node), node=node) for i in range(t.length)]


def assemble(em, t: Type, parts: list[Value], node) -> Value:
    """A value of type ``t`` from its scalar components (the inverse of ``components``)."""
    if isinstance(t, ScalarType):
        return parts[0]
    return em.emit_typed("vec.construct", parts, t, node)


def map_scalar(em, fn: Callable[[Value], Value], v: Value, node) -> Value:
    """``fn`` applied to each scalar component of ``v``, reassembled into ``v``'s type."""
    if isinstance(v.type, ScalarType):
        return fn(v)
    return assemble(em, v.type, [fn(c) for c in components(em, v, node)], node)


def require_float(em, v: Value, name: str, node) -> Value:
    """``v`` unchanged if its elements are floats, else a located KdslTypeError."""
    try:
        ok = elem_type(v.type).is_float
    except TypeError:
        ok = False
    if not ok:
        raise em.error(KdslTypeError, f"{name}() needs a float argument, not {v.type}", node)
    return v


def require_numeric(em, v: Value, name: str, node) -> Value:
    """``v`` unchanged if it is a number, vector or matrix (not bool), else an error."""
    if not isinstance(v.type, ScalarType | VectorType | MatrixType) or elem_type(v.type).is_bool:
        raise em.error(KdslTypeError, f"{name}() needs a number, vector or matrix, not {v.type}",
                       node)  # fmt: skip
    return v


def _is_nan(em, x: Value, node) -> Value:
    return em.emit("arith.cmp", x, x, node=node, pred="ne")


def nan_passing(em, x: Value, r: Value, node) -> Value:
    """``r``, except where a float component of ``x`` is NaN: that component stays NaN."""
    if not elem_type(x.type).is_float:
        return r
    if isinstance(x.type, ScalarType):
        return em.emit("arith.select", _is_nan(em, x, node), x, r, node=node)
    xs, rs = components(em, x, node), components(em, r, node)
    parts = [em.emit("arith.select", _is_nan(em, a, node), a, b, node=node) for a, b in zip(xs, rs)]
    return assemble(em, x.type, parts, node)


@TABLE.define("clamp", (3, 3), "``clamp(x, lo, hi)``: ``min(max(x, lo), hi)``; a NaN ``x`` "
              "gives NaN.", "math")  # fmt: skip
def _clamp(em, args, node):
    x, lo, hi = unified(em, args, node)
    require_numeric(em, x, "clamp", node)
    # Warp's operand order, min(max(lo, x), hi): the gradient rules send ties to the
    # second operand, so x gets it at lo and hi gets it at hi (docs/autodiff.md).
    r = em.emit("arith.min", em.emit("arith.max", lo, x, node=node), hi, node=node)
    return nan_passing(em, x, r, node)


def _float_value(em, x: Any, name: str, node) -> Value:
    return require_float(em, float_default(em, x, node), name, node)


@TABLE.define("lerp", (3, 3), "``lerp(a, b, t)``: ``a * (1 - t) + b * t`` (floats, vectors, "
              "matrices, quaternions, transforms; ``t`` a scalar).", "math")  # fmt: skip
def _lerp(em, args, node):
    a, b, t = args
    if is_weak(a) and is_weak(b):
        a, b = float(a), float(b)
    if not (is_weak(a) and is_weak(b)):
        a, b = unified(em, [a, b], node)
        require_float(em, a, "lerp", node)
        t = em.value(t, node, want=elem_type(a.type))
    elif is_weak(t):
        t = float(t)
    one_minus_t = em.binop("sub", 1.0, t, node)
    return em.binop("add", em.binop("mul", a, one_minus_t, node), em.binop("mul", b, t, node), node)


@TABLE.define("smoothstep", (3, 3), "``smoothstep(a, b, x)``: cubic Hermite ``t*t*(3 - 2*t)`` of "
              "``t = clamp((x - a) / (b - a), 0, 1)``.", "math")  # fmt: skip
def _smoothstep(em, args, node):
    if all(is_weak(v) for v in args):
        args = [float(v) for v in args]
    a, b, x = unified(em, args, node)
    require_float(em, x, "smoothstep", node)
    t = em.binop("div", em.binop("sub", x, a, node), em.binop("sub", b, a, node), node)
    t = _clamp(em, [t, 0.0, 1.0], node)
    return em.binop("mul", em.binop("mul", t, t, node),
                    em.binop("sub", 3.0, em.binop("mul", 2.0, t, node), node), node)  # fmt: skip


def _indicator(name: str, pred: str) -> Callable:
    def lower(em, args, node):
        x = require_numeric(em, em.value(args[0], node), name, node)
        et = elem_type(x.type)
        zero, one = em.const(0, et, node), em.const(1, et, node)

        def scalar(c: Value) -> Value:
            cond = em.emit("arith.cmp", c, zero, node=node, pred=pred)
            return em.emit("arith.select", cond, one, zero, node=node)

        return map_scalar(em, scalar, x, node)

    return lower


TABLE.define("step", (1, 1), "1 if ``x < 0`` else 0, in ``x``'s type (so NaN gives 0).", "math")(
    _indicator("step", "lt"))  # fmt: skip
TABLE.define("nonzero", (1, 1), "1 if ``x != 0`` else 0, in ``x``'s type (so NaN gives 1).",
             "math")(_indicator("nonzero", "ne"))  # fmt: skip


@TABLE.define("frac", (1, 1), "Fractional part ``x - trunc(x)`` (keeps the sign of ``x``).", "math")
def _frac(em, args, node):
    x = _float_value(em, args[0], "frac", node)
    return em.emit("arith.sub", x, em.emit("math.trunc", x, node=node), node=node)


def _scaled(name: str, factor: float) -> Callable:
    def lower(em, args, node):
        x = _float_value(em, args[0], name, node)
        return em.emit("arith.mul", x, em.const(factor, elem_type(x.type), node), node=node)

    return lower


TABLE.define("degrees", (1, 1), "``x`` radians in degrees: ``x * (180 / pi)``.", "math")(
    _scaled("degrees", 180.0 / math.pi))  # fmt: skip
TABLE.define("radians", (1, 1), "``x`` degrees in radians: ``x * (pi / 180)``.", "math")(
    _scaled("radians", math.pi / 180.0))  # fmt: skip


@TABLE.define("bit_count", (1, 1), "Number of set bits of an integer's two's-complement form "
              "(int32).", "math")  # fmt: skip
def _bit_count(em, args, node):
    return em.emit("math.bit_count", em.value(args[0], node), node=node)
