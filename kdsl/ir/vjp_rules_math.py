"""VJP rules of the ``math`` dialect (see ``kdsl.ir.vjp`` for the interface).

Every op is elementwise, so every rule is written once for scalars, vectors and
matrices. Where a derivative is infinite or undefined the rule gives 0 instead
(a componentwise, branch-free guard); each rule's docstring says where, in one
line. Rules reuse the op's result where the derivative is a function of it
(``exp``, ``sqrt``, ``tanh``, ...). The predicates (``isnan``...) give bools and
have no rule.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from kdsl.ir.core import Operation, Value
from kdsl.ir.types import elem_type
from kdsl.ir.vjp import VjpContext
from kdsl.ir.vjp_helpers import rule, scale, where, zero_where_zero

Adj = Sequence["Value | None"]


def _x_r_g(ctx: VjpContext, op: Operation, adj: Adj) -> tuple[Value, Value, Value]:
    """The operand, the result and the result's adjoint of a unary op."""
    (g,) = adj
    return ctx.primal(op.operands[0]), ctx.primal(op.results[0]), g  # type: ignore[return-value]


def _over(ctx: VjpContext, g: Value, den: Value) -> Value:
    """``g / den`` componentwise, 0 where ``den`` is 0 (the derivative's pole)."""
    return zero_where_zero(ctx, den, ctx.div(g, den))


@rule("math.sqrt")
def _sqrt(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """d sqrt(x) = 1/(2 sqrt(x)). At x == 0: 0."""
    _x, r, g = _x_r_g(ctx, op, adj)
    return [_over(ctx, g, scale(ctx, r, 2.0))]


@rule("math.cbrt")
def _cbrt(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """d cbrt(x) = 1/(3 cbrt(x)^2). At x == 0 (or where the square underflows): 0."""
    _x, r, g = _x_r_g(ctx, op, adj)
    return [_over(ctx, g, scale(ctx, ctx.mul(r, r), 3.0))]


@rule("math.exp")
def _exp(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """d exp(x) = exp(x). Smooth everywhere."""
    _x, r, g = _x_r_g(ctx, op, adj)
    return [ctx.mul(g, r)]


@rule("math.exp2")
def _exp2(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """d 2^x = 2^x ln 2. Smooth everywhere."""
    _x, r, g = _x_r_g(ctx, op, adj)
    return [scale(ctx, ctx.mul(g, r), math.log(2.0))]


def _log_rule(factor: float):
    """The rule of a logarithm whose derivative is ``1/(factor x)``."""

    def vjp(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
        """d log_k(x) = 1/(x ln k). At x == 0: 0."""
        x, _r, g = _x_r_g(ctx, op, adj)
        return [_over(ctx, g, x if factor == 1.0 else scale(ctx, x, factor))]

    return vjp


rule("math.log")(_log_rule(1.0))
rule("math.log2")(_log_rule(math.log(2.0)))
rule("math.log10")(_log_rule(math.log(10.0)))


@rule("math.sin")
def _sin(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """d sin(x) = cos(x). Smooth everywhere."""
    x, _r, g = _x_r_g(ctx, op, adj)
    return [ctx.mul(g, ctx.emit("math.cos", x))]


@rule("math.cos")
def _cos(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """d cos(x) = -sin(x). Smooth everywhere."""
    x, _r, g = _x_r_g(ctx, op, adj)
    return [ctx.neg(ctx.mul(g, ctx.emit("math.sin", x)))]


@rule("math.tan")
def _tan(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """d tan(x) = 1 + tan(x)^2. Finite wherever tan is (the poles are not representable)."""
    _x, r, g = _x_r_g(ctx, op, adj)
    return [ctx.mul(g, ctx.add(ctx.const(1, r.type), ctx.mul(r, r)))]


def _arcsin_slope(ctx: VjpContext, x: Value, g: Value, sign: float) -> Value:
    """``sign * g / sqrt(1 - x^2)``, 0 where ``|x| >= 1``."""
    den = ctx.emit("math.sqrt", ctx.sub(ctx.const(1, x.type), ctx.mul(x, x)))
    slope = ctx.div(g, den)
    if sign < 0:
        slope = ctx.neg(slope)
    one = ctx.const(1, elem_type(x.type))

    def outside(xx: Value) -> Value:
        return ctx.cmp("ge", ctx.emit("math.abs", xx), one)

    return where(ctx, outside, [x], None, slope)


@rule("math.asin")
def _asin(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """d asin(x) = 1/sqrt(1 - x^2). At |x| >= 1: 0."""
    x, _r, g = _x_r_g(ctx, op, adj)
    return [_arcsin_slope(ctx, x, g, 1.0)]


@rule("math.acos")
def _acos(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """d acos(x) = -1/sqrt(1 - x^2). At |x| >= 1: 0."""
    x, _r, g = _x_r_g(ctx, op, adj)
    return [_arcsin_slope(ctx, x, g, -1.0)]


@rule("math.atan")
def _atan(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """d atan(x) = 1/(1 + x^2). Smooth everywhere."""
    x, _r, g = _x_r_g(ctx, op, adj)
    return [ctx.div(g, ctx.add(ctx.const(1, x.type), ctx.mul(x, x)))]


@rule("math.sinh")
def _sinh(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """d sinh(x) = cosh(x). Smooth everywhere."""
    x, _r, g = _x_r_g(ctx, op, adj)
    return [ctx.mul(g, ctx.emit("math.cosh", x))]


@rule("math.cosh")
def _cosh(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """d cosh(x) = sinh(x). Smooth everywhere."""
    x, _r, g = _x_r_g(ctx, op, adj)
    return [ctx.mul(g, ctx.emit("math.sinh", x))]


@rule("math.tanh")
def _tanh(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """d tanh(x) = 1 - tanh(x)^2. Smooth everywhere."""
    _x, r, g = _x_r_g(ctx, op, adj)
    return [ctx.mul(g, ctx.sub(ctx.const(1, r.type), ctx.mul(r, r)))]


def _gauss(ctx: VjpContext, x: Value, g: Value, c: float) -> Value:
    """``g * c * exp(-x^2)``."""
    return scale(ctx, ctx.mul(g, ctx.emit("math.exp", ctx.neg(ctx.mul(x, x)))), c)


@rule("math.erf")
def _erf(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """d erf(x) = 2/sqrt(pi) exp(-x^2). Smooth everywhere."""
    x, _r, g = _x_r_g(ctx, op, adj)
    return [_gauss(ctx, x, g, 2.0 / math.sqrt(math.pi))]


@rule("math.erfc")
def _erfc(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """d erfc(x) = -2/sqrt(pi) exp(-x^2). Smooth everywhere."""
    x, _r, g = _x_r_g(ctx, op, adj)
    return [_gauss(ctx, x, g, -2.0 / math.sqrt(math.pi))]


@rule("math.floor", "math.ceil", "math.trunc", "math.round", "math.rint", "math.sign")
def _piecewise_constant(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """Piecewise constant: 0 everywhere, also at the jumps."""
    return [None]


@rule("math.abs")
def _abs(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """d |x| = sign(x). At x == 0 (either sign of zero): +1."""
    x, _r, g = _x_r_g(ctx, op, adj)
    # math.sign is +1 at both zeros: exactly the documented subgradient.
    return [ctx.mul(g, ctx.emit("math.sign", x))]


@rule("math.copysign")
def _copysign(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """copysign(a, b) = |a| sgn(b): sign(a) sgn(b) for a, 0 for b. At a == 0: +sgn(b)."""
    (g,) = adj
    a, b = ctx.operands(op)
    sgn_b = ctx.emit("math.copysign", ctx.const(1, b.type), b)
    return [ctx.mul(g, ctx.mul(ctx.emit("math.sign", a), sgn_b)), None]


@rule("math.atan2")
def _atan2(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """atan2(y, x): x/(x^2+y^2) for y, -y/(x^2+y^2) for x. At x == y == 0: 0 for both."""
    (g,) = adj
    y, x = ctx.operands(op)
    r2 = ctx.add(ctx.mul(x, x), ctx.mul(y, y))
    scaled = _over(ctx, g, r2)
    return [ctx.mul(scaled, x), ctx.neg(ctx.mul(scaled, y))]
