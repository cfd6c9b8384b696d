"""Lowerings of the ``math`` dialect to CUDA's math library.

Default builds use CUDA's IEEE-exact or few-ulp functions (``sqrtf`` is exact with
``-prec-sqrt=true``); ``fast_math`` builds let NVRTC swap in the fast intrinsics.
float16 is widened to float and rounded back.
"""

from __future__ import annotations

from kdsl.backends.cuda import ctypes_ as CT
from kdsl.backends.cuda.arith import is_f16, lanewise, widened
from kdsl.backends.cuda.emitter import FuncEmitter, Lowering, Source
from kdsl.ir import types as T
from kdsl.ir.core import Operation
from kdsl.ir.lowering import LOWERINGS

CUDA = LOWERINGS.for_backend("cuda")

#: math op -> C function for double (float adds the ``f`` suffix).
_FUNCS = {
    "sqrt": "sqrt", "cbrt": "cbrt", "exp": "exp", "exp2": "exp2", "log": "log",
    "log2": "log2", "log10": "log10", "sin": "sin", "cos": "cos", "tan": "tan",
    "asin": "asin", "acos": "acos", "atan": "atan", "sinh": "sinh", "cosh": "cosh",
    "tanh": "tanh", "erf": "erf", "erfc": "erfc", "floor": "floor", "ceil": "ceil",
    "trunc": "trunc", "round": "round", "rint": "rint", "atan2": "atan2",
    "copysign": "copysign",
}  # fmt: skip


def _libm(name: str):
    def rule(src: Source, et: T.ScalarType, *xs: str) -> str:
        fn = _FUNCS[name] + ("f" if et.bits == 32 else "")
        return f"{fn}({', '.join(xs)})"

    return widened(rule)


def _abs(src: Source, et: T.ScalarType, a: str) -> str:
    if is_f16(et):
        return f"kd_f16{{(unsigned short)({a}.bits & 0x7fffu)}}"
    if et.is_float:
        return f"{'fabsf' if et.bits == 32 else 'fabs'}({a})"
    if not et.is_signed:
        return a
    c = CT.scalar_c(et)  # abs(MIN) wraps to MIN
    return f"({a} < ({c})0 ? ({c})(0u - ({CT.unsigned_c(et)}){a}) : {a})"


def _sign(src: Source, et: T.ScalarType, a: str) -> str:
    c = CT.scalar_c(et)
    if is_f16(et):
        return f"(kd_h2f({a}) < 0.0f ? kd_f16{{0xbc00}} : kd_f16{{0x3c00}})"
    if not et.is_signed and not et.is_float:
        return f"({c})1"
    return f"({a} < ({c})0 ? ({c})-1 : ({c})1)"


def _elementwise(rule) -> Lowering:
    def lower(em: FuncEmitter, op: Operation) -> str:
        rt = op.results[0].type
        et = T.elem_type(rt)
        em.src.ctype(rt)
        xs = em.args(op)
        if isinstance(rt, T.ScalarType):
            return rule(em.src, et, *xs)
        name = f"kd_{op.name.split('.')[1]}"
        ts = [v.type for v in op.operands]
        return f"{lanewise(em.src, name, rule, et, rt, ts)}({', '.join(xs)})"

    return lower


def _predicate(fn: str) -> Lowering:
    def lower(em: FuncEmitter, op: Operation) -> str:
        (a,) = em.args(op)
        if is_f16(op.operands[0].type):
            a = f"kd_h2f({a})"
        return f"{fn}({a})"

    return lower


def _bit_count(em: FuncEmitter, op: Operation) -> str:
    (a,) = em.args(op)
    t = op.operands[0].type
    # Count the two's-complement bits: reinterpret as unsigned of the same width first.
    u = f"({CT.scalar_c(T.ScalarType('uint', t.bits))}){a}"
    return f"__popcll({u})" if t.bits == 64 else f"__popc((unsigned int){u})"


for _name in _FUNCS:
    CUDA.register(f"math.{_name}", _elementwise(_libm(_name)))
CUDA.register("math.abs", _elementwise(_abs))
CUDA.register("math.sign", _elementwise(_sign))
CUDA.register("math.isnan", _predicate("isnan"))
CUDA.register("math.isinf", _predicate("isinf"))
CUDA.register("math.isfinite", _predicate("isfinite"))
CUDA.register("math.bit_count", _bit_count)
