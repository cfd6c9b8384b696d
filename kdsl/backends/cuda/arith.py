"""Lowerings of the ``arith`` dialect to C, following ``kdsl.ir.semantics`` exactly.

Scalar ops are C expressions. Signed integer arithmetic is done on the unsigned
type of the same width and cast back, so overflow wraps (in C it would be
undefined). float16 values are widened to float, computed, and rounded back after
each op (as on the cpu backend). Vector and matrix ops call a helper generated
per op and type (``kd_add(kd_vec3_f32, kd_vec3_f32)``...) that applies the same
scalar rule to each component.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable

import numpy as np

from kdsl.backends.cuda import ctypes_ as CT
from kdsl.backends.cuda import helpers as H
from kdsl.backends.cuda.emitter import FuncEmitter, Lowering, Source
from kdsl.ir import semantics as sem
from kdsl.ir import types as T
from kdsl.ir.core import Operation
from kdsl.ir.lowering import LOWERINGS

CUDA = LOWERINGS.for_backend("cuda")

#: A scalar rule: (source, element type, operand expressions) -> C expression.
ScalarRule = Callable[..., str]

_FI = "__device__ __forceinline__"


def is_f16(et: T.ScalarType) -> bool:
    return et.is_float and et.bits == 16


def widened(rule: ScalarRule) -> ScalarRule:
    """``rule`` computed in float and rounded back to float16 for float16 operands."""

    def apply(src: Source, et: T.ScalarType, *xs: str) -> str:
        if not is_f16(et):
            return rule(src, et, *xs)
        return f"kd_f2h({rule(src, T.F32, *[f'kd_h2f({x})' for x in xs])})"

    return apply


def _wrap_int(op: str) -> ScalarRule:
    """Integer ``a op b`` that wraps (computed unsigned, at least 32 bits)."""

    def rule(src: Source, et: T.ScalarType, a: str, b: str) -> str:
        u = CT.unsigned_c(et)
        return f"({CT.scalar_c(et)})(({u}){a} {op} ({u}){b})"

    return rule


def _infix(op: str) -> ScalarRule:
    return lambda src, et, a, b: f"{a} {op} {b}"


def _call(fn: str, f32: str, f64: str | None = None) -> ScalarRule:
    """A float rule calling ``f32`` (float) or ``f64`` (double) C math functions."""

    def rule(src: Source, et: T.ScalarType, *xs: str) -> str:
        name = f32 if et.bits == 32 else (f64 or fn)
        return f"{name}({', '.join(xs)})"

    return rule


def _helper(get: Callable[[Source], str]) -> ScalarRule:
    return lambda src, et, a, b: f"{get(src)}({a}, {b})"


def _float_floordiv(src: Source, et: T.ScalarType, a: str, b: str) -> str:
    if is_f16(et):  # NumPy rounds the quotient to float16 before flooring
        return f"kd_f2h(floorf(kd_h2f(kd_f2h(kd_h2f({a}) / kd_h2f({b})))))"
    return f"{'floorf' if et.bits == 32 else 'floor'}({a} / {b})"


def _minmax(which: str) -> tuple[ScalarRule, ScalarRule]:
    cmp = "<" if which == "min" else ">"

    def int_rule(src, et, a, b):
        return f"({a} {cmp} {b} ? {a} : {b})"

    def float_rule(src, et, a, b):
        return f"{H.float_minmax(src, which)}({a}, {b})"

    return int_rule, widened(float_rule)


def _bitwise(op: str) -> ScalarRule:
    return lambda src, et, a, b: f"({CT.scalar_c(et)})({a} {op} {b})"


#: op -> (integer rule, float rule); None where the op has no such form.
BINARY: dict[str, tuple[ScalarRule | None, ScalarRule | None]] = {
    "add": (_wrap_int("+"), widened(_infix("+"))),
    "sub": (_wrap_int("-"), widened(_infix("-"))),
    "mul": (_wrap_int("*"), widened(_infix("*"))),
    "div": (_helper(H.int_div), widened(_infix("/"))),
    "floordiv": (_helper(H.int_floordiv), _float_floordiv),
    "mod": (_helper(H.int_mod), widened(_call("fmod", "fmodf"))),
    "pow": (None, widened(_call("pow", "powf"))),
    "min": _minmax("min"),
    "max": _minmax("max"),
    "and": (_bitwise("&"), None),
    "or": (_bitwise("|"), None),
    "xor": (_bitwise("^"), None),
    "shl": (_helper(lambda s: H.shifts(s, "shl")), None),
    "shr": (_helper(lambda s: H.shifts(s, "shr")), None),
}


def scalar_rule(kind: str, et: T.ScalarType) -> ScalarRule:
    """The scalar rule of binary op ``kind`` for element type ``et``."""
    int_rule, float_rule = BINARY[kind]
    rule = float_rule if et.is_float else int_rule
    assert rule is not None, f"arith.{kind} on {et}"
    return rule


def lanewise(
    src: Source, fname: str, rule: ScalarRule, et: T.ScalarType, rt: T.Type, ts: list[T.Type]
) -> str:
    """A helper ``fname(args)`` of result type ``rt`` applying ``rule`` per component.

    ``ts`` are the operand types; a scalar operand is broadcast to every component.
    The helper is an overload, so one name serves every type.
    """
    rc = src.ctype(rt)
    names = "abcdefgh"
    params = ", ".join(f"{src.ctype(t)} {names[i]}" for i, t in enumerate(ts))
    key = f"fn:{fname}({params})"

    def lane(i: int, k: int) -> str:
        return names[i] if isinstance(ts[i], T.ScalarType) else f"{names[i]}.c[{k}]"

    def make() -> str:
        n = CT.count(rt)
        body = rule(src, et, *[lane(i, "i") for i in range(len(ts))])
        return (
            f"{_FI} {rc} {fname}({params}) {{\n  {rc} r;\n"
            f"  for (int i = 0; i < {n}; ++i) r.c[i] = {body};\n  return r;\n}}"
        )

    src.need(key, make)
    return fname


def _binary(kind: str) -> Lowering:
    def lower(em: FuncEmitter, op: Operation) -> str:
        rt = op.results[0].type
        et = T.elem_type(rt)
        rule = scalar_rule(kind, et)
        a, b = em.args(op)
        if is_f16(et):
            em.src.ctype(et)
        if isinstance(rt, T.ScalarType):
            return rule(em.src, et, a, b)
        ts = [v.type for v in op.operands]
        return f"{lanewise(em.src, f'kd_{kind}', rule, et, rt, ts)}({a}, {b})"

    return lower


# -- constants -------------------------------------------------------------------


def constant(t: T.ScalarType, value) -> str:
    """The C literal of a scalar constant, exact (floats by their bits when needed);
    negative ones in parentheses, so they can stand anywhere in an expression."""
    text = _literal(t, sem.np_value(value, t))
    return f"({text})" if text.startswith("-") else text


def _literal(t: T.ScalarType, v) -> str:
    if t.is_bool:
        return "true" if bool(v) else "false"
    if t.is_float:
        return float_literal(t, float(v))
    return int_literal(t, int(v))


def float_literal(t: T.ScalarType, x: float) -> str:
    """An exact literal: the shortest decimal that reads back as the value, or its bits."""
    if t.bits == 16:
        return H.const_bits(t, int(np.float16(x).view(np.uint16)))
    if not math.isfinite(x):
        if t.bits == 32:
            return H.const_bits(t, struct.unpack("<I", struct.pack("<f", x))[0])
        return H.const_bits(t, struct.unpack("<Q", struct.pack("<d", x))[0])
    text = str(np.float32(x)) if t.bits == 32 else repr(x)
    if "e" not in text and "." not in text:
        text += ".0"
    return f"{text}f" if t.bits == 32 else text


def int_literal(t: T.ScalarType, x: int) -> str:
    c = CT.scalar_c(t)
    if t.bits == 64:
        if t.is_signed:
            if x == -(2**63):
                return "(-9223372036854775807ll - 1ll)"
            return f"{x}ll"
        return f"{x}ull"
    if t.bits == 32:
        if t.is_signed:
            return "(-2147483647 - 1)" if x == -(2**31) else str(x)
        return f"{x}u"
    return f"({c}){x}"


def _constant(em: FuncEmitter, op: Operation) -> str:
    t = op.results[0].type
    em.src.ctype(t)
    return constant(t, op.attrs["value"])


# -- unary, compare, cast, select ---------------------------------------------------


def _neg_scalar(src: Source, et: T.ScalarType, a: str) -> str:
    if is_f16(et):  # flip the sign bit, exactly like a float negation
        return f"kd_f16{{(unsigned short)({a}.bits ^ 0x8000u)}}"
    if et.is_float:
        return f"-{a}"
    return f"({CT.scalar_c(et)})(0u - ({CT.unsigned_c(et)}){a})"


def _neg(em: FuncEmitter, op: Operation) -> str:
    rt = op.results[0].type
    et = T.elem_type(rt)
    (a,) = em.args(op)
    em.src.ctype(rt)
    if isinstance(rt, T.ScalarType):
        return _neg_scalar(em.src, et, a)
    return f"{lanewise(em.src, 'kd_neg', _neg_scalar, et, rt, [rt])}({a})"


def _not(em: FuncEmitter, op: Operation) -> str:
    return f"!{em.get(op.operands[0])}"


def _bitnot(em: FuncEmitter, op: Operation) -> str:
    t = op.results[0].type
    return f"({CT.scalar_c(t)})~{em.get(op.operands[0])}"


_CMP = {"eq": "==", "ne": "!=", "lt": "<", "le": "<=", "gt": ">", "ge": ">="}


def compare(et: T.ScalarType, pred: str, a: str, b: str) -> str:
    """A scalar comparison (NaN: ordered predicates false, ``ne`` true, as in C)."""
    if is_f16(et):
        a, b = f"kd_h2f({a})", f"kd_h2f({b})"
    return f"{a} {_CMP[pred]} {b}"


def _cmp(em: FuncEmitter, op: Operation) -> str:
    a, b = em.args(op)
    t = op.operands[0].type
    pred = op.attrs["pred"]
    et = T.elem_type(t)
    if isinstance(t, T.ScalarType):
        return compare(et, pred, a, b)
    # Whole-value eq / ne of vectors and matrices.
    ct = em.ctype(t)
    name = f"kd_{pred}"
    n = CT.count(t)
    join = " && " if pred == "eq" else " || "

    def make() -> str:
        lanes = join.join(compare(et, pred, f"a.c[{i}]", f"b.c[{i}]") for i in range(n))
        return f"{_FI} bool {name}({ct} a, {ct} b) {{ return {lanes}; }}"

    em.src.need(f"fn:{name}({ct})", make)
    return f"{name}({a}, {b})"


_F2I = {  # float -> saturating int conversions (NaN gives 0), round toward zero
    (32, True, 32): "__float2int_rz", (32, False, 32): "__float2uint_rz",
    (32, True, 64): "__float2ll_rz", (32, False, 64): "__float2ull_rz",
    (64, True, 32): "__double2int_rz", (64, False, 32): "__double2uint_rz",
    (64, True, 64): "__double2ll_rz", (64, False, 64): "__double2ull_rz",
}  # fmt: skip


def cast_scalar(src: Source, a: str, s: T.ScalarType, d: T.ScalarType) -> str:
    """C converting scalar ``a`` from ``s`` to ``d`` with kdsl's rules (``semantics``)."""
    dc = CT.scalar_c(d)
    if s == d:
        return a
    if is_f16(s):
        if d.is_bool:
            return f"(kd_h2f({a}) != 0.0f)"
        return cast_scalar(src, f"kd_h2f({a})", T.F32, d)
    if d.is_bool:
        return f"({a} != 0)"
    if s.is_bool:
        return cast_scalar(src, f"(int){a}", T.I32, d)
    if is_f16(d):
        H.need_f16(src)
        if s.bits == 64 and s.is_float:
            return f"kd_d2h({a})"
        return f"kd_f2h((float){a})"
    if s.is_float and d.is_float:
        return f"({dc}){a}"
    if s.is_float:
        # The cvt.rzi conversions saturate, but on the GPU they give the type's lowest
        # value (signed) or 2**(bits-1) (unsigned) for NaN; kdsl's cast gives 0.
        wide = 64 if d.bits == 64 else 32
        conv = _F2I[(s.bits, d.is_signed, wide)]
        if d.bits >= 32:
            return f"(({a}) != ({a}) ? ({dc})0 : {conv}({a}))"
        info = np.iinfo(d.np_dtype)
        wc = "int" if d.is_signed else "unsigned int"
        low = f"{info.min}" if d.is_signed else "0u"
        sat = f"kd_clamp<{wc}>({conv}({a}), {low}, {info.max}{'' if d.is_signed else 'u'})"
        return f"({dc})(({a}) != ({a}) ? ({wc})0 : {sat})"
    return f"({dc}){a}"  # int to float rounds to nearest; int to int wraps


#: CUDA's bit-reinterpreting intrinsics: (float bits, to integer or from it).
_FLOAT_BITS = {32: ("__float_as_int", "__int_as_float"), 64: ("__double_as_longlong",
               "__longlong_as_double")}  # fmt: skip


def bitcast_scalar(src: Source, a: str, s: T.ScalarType, d: T.ScalarType) -> str:
    """C reinterpreting the bits of scalar ``a`` (type ``s``) as a ``d`` of the same width."""
    if s == d:
        return a
    dc = CT.scalar_c(d)
    if is_f16(s):  # kd_f16 holds the half's bits
        bits = f"{a}.bits"
    elif s.is_float:
        bits = f"{_FLOAT_BITS[s.bits][0]}({a})"
    else:
        bits = a
    if is_f16(d):
        H.need_f16(src)
        return f"kd_f16{{(unsigned short)({bits})}}"
    if d.is_float:
        wide = "int" if d.bits == 32 else "long long"
        return f"{_FLOAT_BITS[d.bits][1]}(({wide})({bits}))"
    return f"({dc})({bits})"  # integers of one width: two's complement, bits unchanged


def _clamp(src: Source) -> None:
    src.need(
        "kd_clamp",
        lambda: (
            f"template <typename T> {_FI} T kd_clamp(T x, T lo, T hi) "
            "{ return x < lo ? lo : (x > hi ? hi : x); }"
        ),
    )


def _cast(em: FuncEmitter, op: Operation) -> str:
    s_t, d_t = op.operands[0].type, op.results[0].type
    s, d = T.elem_type(s_t), T.elem_type(d_t)
    (a,) = em.args(op)
    em.src.ctype(d_t)
    if s.is_float and d.is_int and d.bits < 32:
        _clamp(em.src)
    if isinstance(d_t, T.ScalarType):
        return cast_scalar(em.src, a, s, d)
    rule = lambda src, et, x: cast_scalar(src, x, s, d)  # noqa: E731
    return f"{lanewise(em.src, 'kd_cast_' + CT.tag(d), rule, d, d_t, [s_t])}({a})"


def _select(em: FuncEmitter, op: Operation) -> str:
    c, a, b = em.args(op)
    return f"{c} ? {a} : {b}"


CUDA.register("arith.constant", _constant)
for _name in BINARY:
    CUDA.register(f"arith.{_name}", _binary(_name))
CUDA.register("arith.neg", _neg)
CUDA.register("arith.not", _not)
CUDA.register("arith.bitnot", _bitnot)
CUDA.register("arith.cmp", _cmp)
CUDA.register("arith.cast", _cast)
CUDA.register(
    "arith.bitcast",
    lambda em, op: bitcast_scalar(em.src, em.args(op)[0], op.operands[0].type, op.results[0].type),
)
CUDA.register("arith.select", _select)
