"""float32 ``sin`` and ``cos`` inline: one range reduction for both, no libm call.

``llvm.sin.f32`` and ``llvm.cos.f32`` become calls of the C library's ``sinf``,
``cosf`` or ``sincosf``. A call costs more than the function: every float register
is caller-saved on x86-64, so a loop around it (the ocean's sum over waves) spills
and reloads its live values each iteration, and a loop with a call is not vectorized.
Here both are one small internal LLVM function, ``kdsl.sincosf``, returning
``{sin x, cos x}``, inlined always and marked ``readnone``, so a ``sin`` and a ``cos``
of the same value are one call after LLVM's common-subexpression elimination and
share the reduction and both polynomials (``sin x`` alone needs both too: it is
``+-cos r`` in odd quadrants). It calls nothing, so a loop of independent elements
(a kernel's thread loop) vectorizes.

For ``|x| < FAST_BOUND`` (2^20) it works in float64: ``n = rint(x * 2/pi)``, then
Cody-Waite ``r = (x - n*PIO2_HI) - n*PIO2_LO`` with a 33-bit ``HI`` (``n < 2^20``, so
``n * HI`` and ``x - n * HI`` are exact, fused or not) and ``LO = pi/2 - HI`` in
float64: ``r``'s error is below 2^-65 absolute, against ``|r| > 2^-28`` for every
float32 ``x`` in range. Beyond it (a branch marked unlikely),
glibc's ``sinf`` reduction: ``|x|`` times 96 bits of 4/pi from a 24-word table in
integer arithmetic (``_reduce_large``); infinities and NaN give NaN there. Then
``sin r = r (1 + r^2 S(r^2))`` and ``cos r = 1 + r^2 C(r^2)`` on ``|r| <= pi/4``
(``S``, ``C``: four coefficients each, near-minimax, ``tools/fit_sincos.py``;
approximation error below 2^-32 relative) and the quadrant ``n mod 4`` picks and
signs them. The float64 result is rounded once to float32: at most 0.5032 ulp over
every float32 with ``0.5 <= |x| < 2^20`` (``tools/sincos_accuracy.py``; glibc's
``sinf``: 0.56). ``+-0`` and denormals come back exactly (``sin(-0) = -0``).

No instruction of the function carries fast-math flags, in ``fast_math`` kernels too
(``reassoc`` would undo the reduction); it only gets the kernel's fast-math function
attributes, so inlining it leaves the kernel's own attributes as they were.
"""

from __future__ import annotations

from llvmlite import ir

from kdsl.backends.cpu import types as LT
from kdsl.backends.cpu.emitter import Emitter, ModuleState, mark_fast_math

#: The Cody-Waite path's bound on ``|x|``; beyond it, the table's reduction.
FAST_BOUND = 2.0**20
#: ``1.5 * 2^52``: adding it rounds a float64 below 2^51 in magnitude to an integer.
ROUNDER = float.fromhex("0x1.8p52")
#: float64 ``2/pi``.
TWO_OVER_PI = float.fromhex("0x1.45f306dc9c883p-1")
#: ``pi/2 ~ HI + LO``: ``HI`` has 33 significant bits, ``LO`` is ``pi/2 - HI`` in float64.
PIO2_HI = float.fromhex("0x1.921fb54400000p+0")
PIO2_LO = float.fromhex("0x1.0b4611a626331p-34")
#: 192 bits of 4/pi (``floor(4/pi 2^191)``).
INV_PIO4 = 0xA2F9836E4E441529FC2757D1F534DDC0DB6295993C439041
#: The large-argument table: word ``k`` is the 32 bits of ``INV_PIO4`` ending at bit
#: ``8 (k + 1)`` from the top (glibc's ``__inv_pio4``).
INV_PIO4_WORDS = tuple((INV_PIO4 >> (192 - 8 * (k + 1))) & 0xFFFFFFFF for k in range(24))
#: ``2 pi 2^-64``: one unit of the 2.62 fixed-point remainder, in radians.
PI_2_POW_M64 = float.fromhex("0x1.921fb54442d18p-62")
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
#: The LLVM name of its table of 4/pi.
TABLE_SYMBOL = "kdsl.sincosf.inv_pio4"
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
    fast, large, join = (fn.append_basic_block(n) for n in ("fast", "large", "join"))
    fabs = state.declare("llvm.fabs.f32", ir.FunctionType(LT.F32, [LT.F32]))
    ax = b.call(fabs, [x])
    small = b.fcmp_ordered("<", ax, ir.Constant(LT.F32, FAST_BOUND))
    b.cbranch(small, fast, large).set_weights([1 << 20, 1])

    b.position_at_end(fast)
    r_fast, q_fast = _reduce_small(b, state, b.fpext(x, _F64))
    b.branch(join)

    b.position_at_end(large)
    r_large, q_large = _reduce_large(b, state, x, ax)
    b.branch(join)

    b.position_at_end(join)
    r, q = b.phi(_F64), b.phi(LT.I32)
    r.add_incoming(r_fast, fast)
    r.add_incoming(r_large, large)
    q.add_incoming(q_fast, fast)
    q.add_incoming(q_large, large)
    b.ret(_pack(b, *_evaluate(b, state, r, q)))
    return fn


def _c(v: float) -> ir.Constant:
    return ir.Constant(_F64, v)


def _i(t: ir.IntType, v: int) -> ir.Constant:
    return ir.Constant(t, v)


def _reduce_small(b: ir.IRBuilder, state: ModuleState, d: ir.Value) -> tuple[ir.Value, ir.Value]:
    """``(r, n mod 2^32)``, ``d = n pi/2 + r``, for the float64 ``d`` (``|d| < FAST_BOUND``).

    Multiply-adds are ``llvm.fmuladd`` (fused where the host has FMA): the reduction is
    exact either way, and fusing only shortens the latency, which bounds a loop that
    evaluates one angle per iteration. ``t = d * 2/pi + 1.5 * 2^52`` rounds to the
    integer ``n`` in its low bits (no rounding instruction).
    """
    fma = _fmuladd(state)
    t = b.call(fma, [d, _c(TWO_OVER_PI), _c(ROUNDER)])
    n = b.fsub(t, _c(ROUNDER))
    r = d
    for part in (PIO2_HI, PIO2_LO):
        r = b.call(fma, [b.fneg(n), _c(part), r])
    return r, b.trunc(b.bitcast(t, LT.I64), LT.I32)


def _reduce_large(
    b: ir.IRBuilder, state: ModuleState, x: ir.Value, ax: ir.Value
) -> tuple[ir.Value, ir.Value]:
    """``(r, n mod 4)`` for ``|x| >= FAST_BOUND`` (Payne-Hanek, as glibc's ``sinf``).

    ``|x| = m 2^e`` (24-bit ``m``) times the 96 bits of 4/pi that matter at ``e``
    (``INV_PIO4``) gives ``|x| 2/pi`` modulo 4 as a 2.62 fixed-point number: its top two
    bits are the quadrant, the rest (rounded to nearest, signed) the remainder, exact
    to 33 bits or more. The sign of ``x`` negates both. Infinities and NaN give NaN.
    """
    i32, i64 = LT.I32, LT.I64
    xi = b.bitcast(ax, i32)
    table = _inv_pio4(state)
    first = b.and_(b.lshr(xi, _i(i32, 26)), _i(i32, 15))
    shift = b.and_(b.lshr(xi, _i(i32, 23)), _i(i32, 7))
    m = b.shl(b.or_(b.and_(xi, _i(i32, 0xFFFFFF)), _i(i32, 0x800000)), shift)

    def word(k: int) -> ir.Value:
        at = b.add(first, _i(i32, k))
        return b.load(b.gep(table, [_i(i32, 0), at], inbounds=True))

    m64 = b.zext(m, i64)
    res0 = b.zext(b.mul(m, word(0)), i64)  # low 32 bits only
    res1 = b.mul(m64, b.zext(word(4), i64))
    res2 = b.mul(m64, b.zext(word(8), i64))
    res = b.add(b.or_(b.lshr(res2, _i(i64, 32)), b.shl(res0, _i(i64, 32))), res1)
    n = b.lshr(b.add(res, _i(i64, 1 << 61)), _i(i64, 62))
    frac = b.sub(res, b.shl(n, _i(i64, 62)))
    r = b.fmul(b.sitofp(frac, _F64), _c(PI_2_POW_M64))
    finite = b.fcmp_ordered("<", ax, ir.Constant(LT.F32, float("inf")))
    r = b.select(finite, r, _c(float("nan")))
    q = b.trunc(n, i32)
    neg = b.icmp_signed("<", b.bitcast(x, i32), _i(i32, 0))
    return b.select(neg, b.fneg(r), r), b.select(neg, b.neg(q), q)


def _inv_pio4(state: ModuleState) -> ir.GlobalVariable:
    """The module's constant table ``INV_PIO4_WORDS`` (``[24 x i32]``), made on first use."""
    found = state.llmod.globals.get(TABLE_SYMBOL)
    if found is not None:
        return found
    ty = ir.ArrayType(LT.I32, len(INV_PIO4_WORDS))
    table = ir.GlobalVariable(state.llmod, ty, TABLE_SYMBOL)
    table.global_constant = True
    table.linkage = "internal"
    table.initializer = ir.Constant(ty, list(INV_PIO4_WORDS))
    return table


def _evaluate(
    b: ir.IRBuilder, state: ModuleState, r: ir.Value, q: ir.Value
) -> tuple[ir.Value, ir.Value]:
    """float32 ``(sin, cos)`` of ``q pi/2 + r`` (``|r| <= pi/4``, float64).

    The polynomials go by Estrin's scheme, two levels instead of four.
    """
    fma = _fmuladd(state)
    u = b.fmul(r, r)
    u2 = b.fmul(u, u)

    def estrin(k: tuple[float, ...]) -> ir.Value:  # k0 + k1 u + k2 u^2 + k3 u^3
        low, high = (b.call(fma, [u, _c(k[i + 1]), _c(k[i])]) for i in (0, 2))
        return b.call(fma, [u2, high, low])

    # Isomorphic pairs (sin, cos), the sign flips integer xors: LLVM packs the flips of
    # both into one vector op (the ocean kernel's loop: about 12% faster than selects).
    w_s = b.call(fma, [u, estrin(SIN_COEFFS), _c(1.0)])
    w_c = b.call(fma, [u, estrin(COS_COEFFS), _c(1.0)])
    # r (1 + u S), not r + r u S: that gives sin(-0) = +0.
    sin_r, cos_r = b.fmul(r, w_s), w_c
    i64 = LT.I64
    q64 = b.zext(q, i64)
    odd = b.icmp_unsigned("!=", b.and_(q64, _i(i64, 1)), _i(i64, 0))
    sin_q, cos_q = b.select(odd, cos_r, sin_r), b.select(odd, sin_r, cos_r)
    # sin x = +-sin_q (negative in quadrants 2, 3), cos x = +-cos_q (quadrants 1, 2).
    sign = _i(i64, 1 << 63)
    s_bits = b.and_(b.shl(q64, _i(i64, 62)), sign)
    c_bits = b.and_(b.shl(b.add(q64, _i(i64, 1)), _i(i64, 62)), sign)
    sin_x = b.bitcast(b.xor(b.bitcast(sin_q, i64), s_bits), _F64)
    cos_x = b.bitcast(b.xor(b.bitcast(cos_q, i64), c_bits), _F64)
    return b.fptrunc(sin_x, LT.F32), b.fptrunc(cos_x, LT.F32)


def _fmuladd(state: ModuleState) -> ir.Function:
    return state.declare("llvm.fmuladd.f64", ir.FunctionType(_F64, [_F64] * 3))


def _pack(b: ir.IRBuilder, sin: ir.Value, cos: ir.Value) -> ir.Value:
    return b.insert_value(b.insert_value(ir.Constant(_PAIR, ir.Undefined), sin, 0), cos, 1)
