"""Lowerings of the ``arith`` dialect, following ``kdsl.ir.semantics`` exactly.

Integer division never traps: a zero divisor (and ``MIN / -1``) is replaced
with a safe one under a ``select``, and the result picked afterwards. float16
arithmetic is done in float32 and rounded back after each op, as NumPy does.
Vector and matrix operands are ``composite.Parts``: every op is applied per
component (``em.map``), so the emitters below only ever see scalars.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from llvmlite import ir

from kdsl.backends.cpu import types as LT
from kdsl.backends.cpu.composite import Parts, leaves, rebuild
from kdsl.backends.cpu.emitter import Emitter, Lowering
from kdsl.ir import semantics as sem
from kdsl.ir import types as T
from kdsl.ir.core import Operation
from kdsl.ir.lowering import LOWERINGS

CPU = LOWERINGS.for_backend("cpu")

_HALF = ir.HalfType()

#: The C math functions LLVM may lower these lowerings' float operations to (``jit``
#: resolves them): ``llvm.pow`` -> ``pow``, ``frem`` -> ``fmod``, float min/max ->
#: ``fmin``/``fmax``.
C_FUNCTIONS = ("pow", "fmod", "fmin", "fmax")


def widen_half(em: Emitter, et: T.ScalarType, fn: Callable[..., Any], *vals: Any):
    """``fn(*vals)``, computed in float32 and rounded back when ``et`` is float16.

    ``vals`` and the result may be scalars or ``Parts``; each component is widened.
    """
    if not (et.is_float and et.bits == 16):
        return fn(*vals)
    wide = [em.map(lambda x: em.b.fpext(x, LT.F32), v) for v in vals]
    return em.map(lambda x: em.b.fptrunc(x, _HALF), fn(*wide))


def binary(int_fn: Callable | None, float_fn: Callable | None) -> Lowering:
    """A lowering for an elementwise binary op given its int and float emitters.

    Each emitter is ``fn(em, et, a, b)``; float16 is widened around ``float_fn``.
    """

    def scalar(em: Emitter, et: T.ScalarType, a: ir.Value, b: ir.Value) -> ir.Value:
        if et.is_float:
            return widen_half(em, et, lambda x, y: float_fn(em, et, x, y), a, b)
        return int_fn(em, et, a, b)

    def lower(em: Emitter, op: Operation) -> Any:
        et = T.elem_type(op.results[0].type)
        return em.map(lambda a, b: scalar(em, et, a, b), *em.args(op))

    return lower


def _consts(em: Emitter, t: ir.Type, *values: int) -> list[ir.Value]:
    return [em.const(t, v) for v in values]


def _safe_divisor(em: Emitter, et: T.ScalarType, b: ir.Value):
    """(divisor with 0 and -1 replaced by 1, b == 0, b == -1 or None)."""
    B = em.b
    zero, one, m1 = _consts(em, b.type, 0, 1, -1)
    is_zero = B.icmp_unsigned("==", b, zero)
    if not et.is_signed:
        return B.select(is_zero, one, b), is_zero, None
    is_m1 = B.icmp_signed("==", b, m1)
    return B.select(B.or_(is_zero, is_m1), one, b), is_zero, is_m1


def _quotient(em: Emitter, et: T.ScalarType, a: ir.Value, b: ir.Value, floor: bool) -> ir.Value:
    """``a / b`` truncated toward zero, or floored; ``x / 0`` is 0 and ``MIN / -1`` wraps."""
    B = em.b
    safe, is_zero, is_m1 = _safe_divisor(em, et, b)
    if not et.is_signed:
        q = B.udiv(a, safe)
    else:
        q = B.sdiv(a, safe)
        if floor:
            r = B.srem(a, safe)
            zero = em.const(a.type, 0)
            # Round down when the remainder is nonzero and its sign differs from b's.
            adjust = B.and_(B.icmp_signed("!=", r, zero), B.icmp_signed("<", B.xor(r, safe), zero))
            q = B.sub(q, B.zext(adjust, a.type))
        q = B.select(is_m1, B.neg(a), q)
    return B.select(is_zero, em.const(a.type, 0), q)


def int_div(em: Emitter, et: T.ScalarType, a: ir.Value, b: ir.Value) -> ir.Value:
    """C division truncating toward zero; ``x / 0`` is 0 and ``MIN / -1`` wraps."""
    return _quotient(em, et, a, b, floor=False)


def int_floordiv(em: Emitter, et: T.ScalarType, a: ir.Value, b: ir.Value) -> ir.Value:
    """Floor division; ``x // 0`` is 0."""
    return _quotient(em, et, a, b, floor=True)


def int_mod(em: Emitter, et: T.ScalarType, a: ir.Value, b: ir.Value) -> ir.Value:
    """C remainder (sign of the dividend); ``x % 0`` is 0."""
    B = em.b
    safe, is_zero, _ = _safe_divisor(em, et, b)
    r = B.srem(a, safe) if et.is_signed else B.urem(a, safe)
    return B.select(is_zero, em.const(a.type, 0), r)


def float_floordiv(em: Emitter, et: T.ScalarType, a: ir.Value, b: ir.Value) -> ir.Value:
    q = em.b.fdiv(a, b)
    if et.bits == 16:  # NumPy rounds the quotient to float16 before flooring
        q = em.b.fpext(em.b.fptrunc(q, _HALF), q.type)
    return em.call_intrinsic("llvm.floor", q)


def _shift_amount(em: Emitter, et: T.ScalarType, s: ir.Value) -> ir.Value:
    """True where the shift amount is out of range (negative or at least the width)."""
    # Compared unsigned, a negative amount is huge, so one compare covers both.
    return em.b.icmp_unsigned(">=", s, em.const(s.type, et.bits))


def shl(em: Emitter, et: T.ScalarType, a: ir.Value, s: ir.Value) -> ir.Value:
    big = _shift_amount(em, et, s)
    safe = em.b.select(big, em.const(s.type, 0), s)
    return em.b.select(big, em.const(a.type, 0), em.b.shl(a, safe))


def shr(em: Emitter, et: T.ScalarType, a: ir.Value, s: ir.Value) -> ir.Value:
    big = _shift_amount(em, et, s)
    if et.is_signed:  # shifting by width-1 gives the sign fill (0 or -1)
        return em.b.ashr(a, em.b.select(big, em.const(s.type, et.bits - 1), s))
    safe = em.b.select(big, em.const(s.type, 0), s)
    return em.b.select(big, em.const(a.type, 0), em.b.lshr(a, safe))


def _minmax(smin: str, umin: str, fmin: str) -> Lowering:
    def int_fn(em, et, a, b):
        return em.call_intrinsic(smin if et.is_signed else umin, a, b)

    def float_fn(em, et, a, b):
        return em.call_intrinsic(fmin, a, b)

    return binary(int_fn, float_fn)


def _constant(em: Emitter, op: Operation) -> ir.Value:
    t = op.results[0].type
    v = sem.np_value(op.attrs["value"], t)
    lt = LT.llvm_type(t)
    if t.is_bool:
        return ir.Constant(lt, int(bool(v)))
    if t.is_float:
        return ir.Constant(lt, float(v))
    # Unsigned values above the signed range are written as their signed twin.
    return ir.Constant(lt, int(np.asarray(v).astype(f"i{t.bits // 8}")))


def _neg(em: Emitter, op: Operation) -> Any:
    (a,) = em.args(op)
    et = T.elem_type(op.results[0].type)
    return em.map(em.b.fneg if et.is_float else em.b.neg, a)


def _not(em: Emitter, op: Operation) -> Any:
    (a,) = em.args(op)
    return em.map(em.b.not_, a)


_PRED = {"eq": "==", "ne": "!=", "lt": "<", "le": "<=", "gt": ">", "ge": ">="}


def compare(em: Emitter, et: T.ScalarType, pred: str, a: ir.Value, b: ir.Value) -> ir.Value:
    """Elementwise comparison (NaN: ordered predicates false, ``ne`` true)."""
    B = em.b
    p = _PRED[pred]
    if et.is_float:
        return B.fcmp_unordered(p, a, b) if pred == "ne" else B.fcmp_ordered(p, a, b)
    if et.is_signed:
        return B.icmp_signed(p, a, b)
    return B.icmp_unsigned(p, a, b)


def _cmp(em: Emitter, op: Operation) -> ir.Value:
    a, b = em.args(op)
    pred = op.attrs["pred"]
    et = T.elem_type(op.operands[0].type)
    r = em.map(lambda x, y: compare(em, et, pred, x, y), a, b)
    if not isinstance(r, Parts):
        return r
    # Whole-value eq (all components equal) / ne (any component differs).
    join = em.b.and_ if pred == "eq" else em.b.or_
    out = r[0]
    for x in r.items[1:]:
        out = join(out, x)
    return out


def cast(em: Emitter, a: ir.Value, src: T.ScalarType, dst: T.ScalarType) -> ir.Value:
    """Convert the scalar ``a`` from ``src`` to ``dst`` with kdsl's rules."""
    B = em.b
    to = LT.scalar_type(dst)
    if src == dst:
        return a
    if dst.is_bool:
        zero = em.const(a.type, 0.0 if src.is_float else 0)
        if src.is_float:
            return B.fcmp_unordered("!=", a, zero)
        return B.icmp_unsigned("!=", a, zero)
    if src.is_bool:
        return B.uitofp(a, to) if dst.is_float else B.zext(a, to)
    if src.is_float and dst.is_float:
        return B.fpext(a, to) if dst.bits > src.bits else B.fptrunc(a, to)
    if src.is_float:
        if src.bits == 16:
            a = B.fpext(a, LT.F32)
        name = "llvm.fptosi.sat" if dst.is_signed else "llvm.fptoui.sat"
        return B.call(em.intrinsic(name, [to, a.type], to, [a.type]), [a])
    if dst.is_float:
        return B.sitofp(a, to) if src.is_signed else B.uitofp(a, to)
    if dst.bits < src.bits:
        return B.trunc(a, to)
    if dst.bits > src.bits:
        return B.sext(a, to) if src.is_signed else B.zext(a, to)
    return a  # same width, other signedness: same bits


def _cast(em: Emitter, op: Operation) -> Any:
    (a,) = em.args(op)
    src, dst = T.elem_type(op.operands[0].type), T.elem_type(op.results[0].type)
    return em.map(lambda x: cast(em, x, src, dst), a)


def _select(em: Emitter, op: Operation) -> Any:
    c, a, b = em.args(op)
    picked = (em.b.select(c, x, y) for x, y in zip(leaves(a), leaves(b)))
    return rebuild(op.results[0].type, picked)


def _method(name: str) -> Callable:
    """An emitter ``fn(em, et, a, b)`` calling the IRBuilder method ``name``."""
    return lambda em, et, a, b: getattr(em.b, name)(a, b)


CPU.register("arith.constant", _constant)
CPU.register("arith.add", binary(_method("add"), _method("fadd")))
CPU.register("arith.sub", binary(_method("sub"), _method("fsub")))
CPU.register("arith.mul", binary(_method("mul"), _method("fmul")))
CPU.register("arith.div", binary(int_div, _method("fdiv")))
CPU.register("arith.floordiv", binary(int_floordiv, float_floordiv))
CPU.register("arith.mod", binary(int_mod, _method("frem")))
CPU.register("arith.pow", binary(None, lambda em, et, a, b: em.call_intrinsic("llvm.pow", a, b)))
CPU.register("arith.min", _minmax("llvm.smin", "llvm.umin", "llvm.minimumnum"))
CPU.register("arith.max", _minmax("llvm.smax", "llvm.umax", "llvm.maximumnum"))
CPU.register("arith.and", binary(_method("and_"), None))
CPU.register("arith.or", binary(_method("or_"), None))
CPU.register("arith.xor", binary(_method("xor"), None))
CPU.register("arith.shl", binary(shl, None))
CPU.register("arith.shr", binary(shr, None))
CPU.register("arith.neg", _neg)
CPU.register("arith.not", _not)
CPU.register("arith.bitnot", _not)
CPU.register("arith.cmp", _cmp)
CPU.register("arith.cast", _cast)
CPU.register(
    "arith.bitcast", lambda em, op: em.b.bitcast(em.args(op)[0], LT.llvm_type(op.results[0].type))
)
CPU.register("arith.select", _select)
