"""Lowerings of the ``math`` dialect: LLVM intrinsics where LLVM has an exact one,
the C math library (through symbols the JIT resolves, see ``jit``) for the rest.
float32 and float16 ``sin`` and ``cos`` are computed inline (``trig``; float64 keeps
``llvm.sin``/``llvm.cos``). Vector and matrix operands are lowered one scalar
component at a time (``em.map``)."""

from __future__ import annotations

from typing import Any

from llvmlite import ir

from kdsl.backends.cpu import trig
from kdsl.backends.cpu import types as LT
from kdsl.backends.cpu.arith import widen_half
from kdsl.backends.cpu.emitter import Emitter, Lowering
from kdsl.ir import types as T
from kdsl.ir.core import Operation
from kdsl.ir.lowering import LOWERINGS

CPU = LOWERINGS.for_backend("cpu")

#: math op -> LLVM intrinsic (elementwise on vectors, exact IEEE or libm-backed).
INTRINSICS = {
    "sqrt": "llvm.sqrt", "exp": "llvm.exp", "exp2": "llvm.exp2", "log": "llvm.log",
    "log2": "llvm.log2", "log10": "llvm.log10", "sin": "llvm.sin", "cos": "llvm.cos",
    "floor": "llvm.floor", "ceil": "llvm.ceil", "trunc": "llvm.trunc",
    "round": "llvm.round", "rint": "llvm.rint",
}  # fmt: skip

#: math op -> C library function (the ``f`` suffix is added for float32).
LIBM = ("cbrt", "tan", "asin", "acos", "atan", "sinh", "cosh", "tanh", "erf", "erfc")

#: The C math functions these lowerings may call (``jit`` resolves them): the libm
#: calls, and what LLVM lowers the intrinsics to where the target has no instruction
#: (``llvm.sin`` -> ``sin``; ``llvm.rint`` may become ``nearbyint``).
C_FUNCTIONS = (
    *LIBM, "atan2", *(v.removeprefix("llvm.") for v in INTRINSICS.values()), "nearbyint",
)  # fmt: skip


def _intrinsic(name: str) -> Lowering:
    def lower(em: Emitter, op: Operation) -> Any:
        et = T.elem_type(op.results[0].type)
        return em.map(lambda a: widen_half(em, et, lambda x: em.call_intrinsic(name, x), a),
                      *em.args(op))  # fmt: skip

    return lower


def _sincos(index: int, name: str) -> Lowering:
    """``sin`` (``index`` 0) or ``cos`` (1): ``trig`` for float32 and float16, else ``name``."""
    fallback = _intrinsic(name)

    def scalar(em: Emitter, x: ir.Value) -> ir.Value:
        return trig.sincos_f32(em, x)[index]

    def lower(em: Emitter, op: Operation) -> Any:
        et = T.elem_type(op.results[0].type)
        if not (et.is_float and et.bits <= 32):
            return fallback(em, op)
        return em.map(lambda a: widen_half(em, et, lambda x: scalar(em, x), a), *em.args(op))

    return lower


def _libm(name: str) -> Lowering:
    def lower(em: Emitter, op: Operation) -> Any:
        return em.map(lambda *xs: em.libm(name, *xs), *em.args(op))

    return lower


def _componentwise(fn):
    """A lowering applying the scalar emitter ``fn(em, et, a)`` to each component."""

    def lower(em: Emitter, op: Operation) -> Any:
        et = T.elem_type(op.results[0].type)
        return em.map(lambda *xs: fn(em, et, *xs), *em.args(op))

    return lower


def _abs(em: Emitter, et: T.ScalarType, a: ir.Value) -> ir.Value:
    if et.is_float:
        return em.call_intrinsic("llvm.fabs", a)
    if not et.is_signed:
        return a
    poison_min = ir.Constant(LT.I1, 0)  # abs(MIN) wraps to MIN, it is not poison
    fn = em.intrinsic("llvm.abs", [a.type], a.type, [a.type, LT.I1])
    return em.b.call(fn, [a, poison_min])


def _sign(em: Emitter, et: T.ScalarType, a: ir.Value) -> ir.Value:
    if et.is_float:
        neg = em.b.fcmp_ordered("<", a, em.const(a.type, 0.0))
        return em.b.select(neg, em.const(a.type, -1.0), em.const(a.type, 1.0))
    if not et.is_signed:
        return em.const(a.type, 1)
    neg = em.b.icmp_signed("<", a, em.const(a.type, 0))
    return em.b.select(neg, em.const(a.type, -1), em.const(a.type, 1))


def _isnan(em: Emitter, op: Operation) -> ir.Value:
    (a,) = em.args(op)
    return em.b.fcmp_unordered("uno", a, a)


def _isinf(em: Emitter, op: Operation) -> ir.Value:
    (a,) = em.args(op)
    mag = em.call_intrinsic("llvm.fabs", a)
    return em.b.fcmp_ordered("==", mag, em.const(a.type, float("inf")))


def _isfinite(em: Emitter, op: Operation) -> ir.Value:
    (a,) = em.args(op)
    mag = em.call_intrinsic("llvm.fabs", a)
    return em.b.fcmp_ordered("<", mag, em.const(a.type, float("inf")))


def _copysign(em: Emitter, et: T.ScalarType, a: ir.Value, b: ir.Value) -> ir.Value:
    return em.call_intrinsic("llvm.copysign", a, b)


def _bit_count(em: Emitter, op: Operation) -> ir.Value:
    (a,) = em.args(op)
    n = em.call_intrinsic("llvm.ctpop", a)
    width = a.type.width
    if width > 32:
        return em.b.trunc(n, LT.I32)
    return em.b.zext(n, LT.I32) if width < 32 else n


for _name, _intr in INTRINSICS.items():
    if _name not in ("sin", "cos"):
        CPU.register(f"math.{_name}", _intrinsic(_intr))
for _name in LIBM:
    CPU.register(f"math.{_name}", _libm(_name))
CPU.register("math.sin", _sincos(0, INTRINSICS["sin"]))
CPU.register("math.cos", _sincos(1, INTRINSICS["cos"]))
CPU.register("math.abs", _componentwise(_abs))
CPU.register("math.sign", _componentwise(_sign))
CPU.register("math.isnan", _isnan)
CPU.register("math.isinf", _isinf)
CPU.register("math.isfinite", _isfinite)
CPU.register("math.atan2", _libm("atan2"))
CPU.register("math.copysign", _componentwise(_copysign))
CPU.register("math.bit_count", _bit_count)
