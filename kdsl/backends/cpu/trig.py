"""float32 ``sin`` and ``cos`` inline: one range reduction for both, libm beyond a bound.

``llvm.sin.f32`` and ``llvm.cos.f32`` become calls of the C library's ``sinf``,
``cosf`` or ``sincosf``. A call costs more than the function: every float register
is caller-saved on x86-64, so a loop around it (the ocean's sum over waves) spills
and reloads its live values each iteration. Here both are one small internal LLVM
function, ``kdsl.sincosf``, returning ``{sin x, cos x}``, inlined always and marked
``readnone``, so a ``sin`` and a ``cos`` of the same value are one call after LLVM's
common-subexpression elimination and share the reduction and both polynomials
(``sin x`` alone needs both too: it is ``+-cos r`` in odd quadrants).

For ``|x| < FAST_BOUND`` (2^20) it works in float64: ``n = rint(x * 2/pi)``, then
Cody-Waite ``r = x - n*PIO2_HI - n*PIO2_MID - n*PIO2_LO`` with 33-bit ``HI`` and
``MID`` (``n < 2^20``, so ``n * HI`` and ``n * MID`` are exact and ``x - n * HI`` is
exact too: no fused multiply-add is needed), then ``sin r = r (1 + r^2 S(r^2))`` and
``cos r = 1 + r^2 C(r^2)`` on ``|r| <= pi/4`` (``S``, ``C``: four coefficients each,
near-minimax, ``tools/fit_sincos.py``; approximation error below 2^-32 relative) and
the quadrant ``n mod 4`` picks and signs them. The float64 result is rounded once to
float32, so the error is at most about 0.5 ulp plus 2^-8 ulp. ``+-0`` and denormals
come back exactly (``sin(-0) = -0``). NaN, infinities and ``|x| >= FAST_BOUND`` go to
``llvm.sin.f32``/``llvm.cos.f32`` (libm) on a branch marked unlikely.

No instruction of the function carries fast-math flags, in ``fast_math`` kernels too
(``reassoc`` would undo the reduction); it only gets the kernel's fast-math function
attributes, so inlining it leaves the kernel's own attributes as they were.
"""

from __future__ import annotations

from llvmlite import ir

from kdsl.backends.cpu import types as LT
from kdsl.backends.cpu.emitter import Emitter, ModuleState, mark_fast_math

#: The inline path's bound on ``|x|``; beyond it (and for NaN, inf) libm decides.
FAST_BOUND = 2.0**20
#: ``1.5 * 2^52``: adding it rounds a float64 below 2^51 in magnitude to an integer.
ROUNDER = float.fromhex("0x1.8p52")
#: float64 ``2/pi``.
TWO_OVER_PI = float.fromhex("0x1.45f306dc9c883p-1")
#: ``pi/2 = HI + MID + LO``: ``HI`` and ``MID`` have 33 significant bits.
PIO2_HI = float.fromhex("0x1.921fb54400000p+0")
PIO2_MID = float.fromhex("0x1.0b4611a600000p-34")
PIO2_LO = float.fromhex("0x1.3198a2e037073p-69")
#: ``sin r = r (1 + u (S1 + u S2 + u^2 S3 + u^3 S4))``, ``u = r^2``, ``|r| <= pi/4``.
SIN_COEFFS = tuple(float.fromhex(c) for c in (
    "-0x1.555555545e0a4p-3", "0x1.11110def2ce21p-7",
    "-0x1.a013a79210ce9p-13", "0x1.6dbe07aef0c34p-19",
))  # fmt: skip
#: ``cos r = 1 + u (C1 + u C2 + u^2 C3 + u^3 C4)``, ``u = r^2``, ``|r| <= pi/4``.
COS_COEFFS = tuple(float.fromhex(c) for c in (
    "-0x1.fffffffab1d79p-2", "0x1.55554cbb40afep-5",
    "-0x1.6c0e087d110b5p-10", "0x1.9a6f2af32846cp-16",
))  # fmt: skip

#: The LLVM name of the per-module function.
SYMBOL = "kdsl.sincosf"
SLOW_SYMBOL = "kdsl.sincosf.slow"
_F64 = ir.DoubleType()
_PAIR = ir.LiteralStructType([LT.F32, LT.F32])


def sincos_f32(em: Emitter, x: ir.Value) -> tuple[ir.Value, ir.Value]:
    """``(sin x, cos x)`` of the float32 scalar ``x`` (see the module docstring)."""
    fn = em.state.llmod.globals.get(SYMBOL)
    if fn is None:
        fn = _define(em.state)
    pair = em.b.call(fn, [x])
    return em.b.extract_value(pair, 0), em.b.extract_value(pair, 1)


def _define(state: ModuleState) -> ir.Function:
    fn = ir.Function(state.llmod, ir.FunctionType(_PAIR, [LT.F32]), SYMBOL)
    fn.linkage = "internal"
    for attr in ("alwaysinline", "nounwind", "readnone"):
        fn.attributes.add(attr)
    if state.fast_math:
        mark_fast_math(fn)
    (x,) = fn.args
    b = ir.IRBuilder(fn.append_basic_block("entry"))
    fast, slow = fn.append_basic_block("fast"), fn.append_basic_block("slow")
    fabs = _intrinsic(state, "llvm.fabs.f32", LT.F32)
    small = b.fcmp_ordered("<", b.call(fabs, [x]), ir.Constant(LT.F32, FAST_BOUND))
    b.cbranch(small, fast, slow).set_weights([1 << 20, 1])

    b.position_at_end(fast)
    b.ret(_pack(b, *_reduced(b, state, b.fpext(x, _F64))))

    b.position_at_end(slow)
    b.ret(b.call(_slow(state), [x]))
    return fn


def _slow(state: ModuleState) -> ir.Function:
    """``kdsl.sincosf.slow``: ``{llvm.sin.f32 x, llvm.cos.f32 x}`` (libm's ``sincosf``),
    never inlined and not speculatable (the intrinsics are, and the loop vectorizer would
    then call libm on every lane, the fast ones too): a vectorized loop calls it only
    for the lanes that need it."""
    fn = ir.Function(state.llmod, ir.FunctionType(_PAIR, [LT.F32]), SLOW_SYMBOL)
    fn.linkage = "internal"
    for attr in ("noinline", "nounwind", "readnone", "cold"):
        fn.attributes.add(attr)
    if state.fast_math:
        mark_fast_math(fn)
    (x,) = fn.args
    b = ir.IRBuilder(fn.append_basic_block("entry"))
    sin, cos = (b.call(_intrinsic(state, f"llvm.{f}.f32", LT.F32), [x]) for f in ("sin", "cos"))
    b.ret(_pack(b, sin, cos))
    return fn


def _reduced(b: ir.IRBuilder, state: ModuleState, d: ir.Value) -> tuple[ir.Value, ir.Value]:
    """float32 ``(sin, cos)`` of the float64 ``d`` (``|d| < FAST_BOUND``).

    Multiply-adds are ``llvm.fmuladd`` (fused where the host has FMA): the reduction is
    exact either way, and fusing only shortens the latency, which bounds a loop that
    evaluates one angle per iteration. ``t = d * 2/pi + 1.5 * 2^52`` rounds to the
    integer ``n`` in its low bits (no rounding instruction); the polynomials go by
    Estrin's scheme, two levels instead of four.
    """
    fma = _fmuladd(state)

    def c(v: float) -> ir.Constant:
        return ir.Constant(_F64, v)

    t = b.call(fma, [d, c(TWO_OVER_PI), c(ROUNDER)])
    n = b.fsub(t, c(ROUNDER))
    r = d
    for part in (PIO2_HI, PIO2_MID, PIO2_LO):
        r = b.call(fma, [b.fneg(n), c(part), r])
    u = b.fmul(r, r)
    u2 = b.fmul(u, u)

    def estrin(k: tuple[float, ...]) -> ir.Value:  # k0 + k1 u + k2 u^2 + k3 u^3
        low, high = (b.call(fma, [u, c(k[i + 1]), c(k[i])]) for i in (0, 2))
        return b.call(fma, [u2, high, low])

    # r (1 + u S), not r + r u S: that gives sin(-0) = +0 (rounding in float64 is far
    # below float32's anyway).
    sin_r = b.fmul(r, b.call(fma, [u, estrin(SIN_COEFFS), c(1.0)]))
    cos_r = b.call(fma, [u, estrin(COS_COEFFS), c(1.0)])
    q = b.trunc(b.bitcast(t, LT.I64), LT.I32)  # n mod 2^32
    odd = b.icmp_unsigned("!=", b.and_(q, ir.Constant(LT.I32, 1)), ir.Constant(LT.I32, 0))
    sin_q, cos_q = b.select(odd, cos_r, sin_r), b.select(odd, sin_r, cos_r)
    # sin x = +-sin_q (negative in quadrants 2, 3), cos x = +-cos_q (quadrants 1, 2).
    sin_x = _negate_if(b, sin_q, b.and_(q, ir.Constant(LT.I32, 2)))
    cos_x = _negate_if(b, cos_q, b.and_(b.add(q, ir.Constant(LT.I32, 1)), ir.Constant(LT.I32, 2)))
    return b.fptrunc(sin_x, LT.F32), b.fptrunc(cos_x, LT.F32)


def _fmuladd(state: ModuleState) -> ir.Function:
    return state.declare("llvm.fmuladd.f64", ir.FunctionType(_F64, [_F64] * 3))


def _negate_if(b: ir.IRBuilder, v: ir.Value, bit: ir.Value) -> ir.Value:
    neg = b.icmp_unsigned("!=", bit, ir.Constant(LT.I32, 0))
    return b.select(neg, b.fneg(v), v)


def _pack(b: ir.IRBuilder, sin: ir.Value, cos: ir.Value) -> ir.Value:
    return b.insert_value(b.insert_value(ir.Constant(_PAIR, ir.Undefined), sin, 0), cos, 1)


def _intrinsic(state: ModuleState, name: str, t: ir.Type) -> ir.Function:
    return state.declare(name, ir.FunctionType(t, [t]))
