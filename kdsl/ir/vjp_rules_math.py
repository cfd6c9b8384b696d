"""VJP rules of the ``math`` dialect (see ``kdsl.ir.vjp`` for the interface).

Every op is elementwise, so every rule is written once for scalars, vectors and
matrices. Most are unary and written as one line of the table ``_UNARY``: the
adjoint of the operand from the operand, the result and the result's adjoint.
Where a derivative is infinite or undefined the rule gives 0 instead (a
componentwise, branch-free guard); each rule's comment or docstring says where,
in one line. Rules reuse the op's result where the derivative is a function of it
(``exp``, ``sqrt``, ``tanh``, ...). The predicates (``isnan``...) give bools and
have no rule.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

from kdsl.ir.core import Operation, Value
from kdsl.ir.types import elem_type
from kdsl.ir.vjp import VjpContext, VjpRule
from kdsl.ir.vjp_helpers import rule, scale, where, zero_where_zero

Adj = Sequence["Value | None"]


def _x_r_g(ctx: VjpContext, op: Operation, adj: Adj) -> tuple[Value, Value, Value]:
    """The operand, the result and the result's adjoint of a unary op."""
    (g,) = adj
    return ctx.primal(op.operands[0]), ctx.primal(op.results[0]), g  # type: ignore[return-value]


def _over(ctx: VjpContext, g: Value, den: Value) -> Value:
    """``g / den`` componentwise, 0 where ``den`` is 0 (the derivative's pole)."""
    return zero_where_zero(ctx, den, ctx.div(g, den))


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


def _gauss(ctx: VjpContext, x: Value, g: Value, c: float) -> Value:
    """``g * c * exp(-x^2)``."""
    return scale(ctx, ctx.mul(g, ctx.emit("math.exp", ctx.neg(ctx.mul(x, x)))), c)


#: A unary op's adjoint from its operand ``x``, its result ``r`` and the result's adjoint ``g``.
Unary = Callable[[VjpContext, Value, Value, Value], Value]


def _unary(fn: Unary) -> VjpRule:
    """The VJP rule of a unary op from its adjoint (as JAX's ``defjvp`` from a derivative)."""

    def vjp(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
        x, r, g = _x_r_g(ctx, op, adj)
        return [fn(ctx, x, r, g)]

    return vjp


#: The unary ops' adjoints. Each comment gives the derivative and, in one line, where
#: the rule gives 0 instead of an infinite or undefined one.
_UNARY: dict[str, Unary] = {
    # d sqrt(x) = 1/(2 sqrt(x)). At x == 0: 0.
    "math.sqrt": lambda ctx, x, r, g: _over(ctx, g, scale(ctx, r, 2.0)),
    # d cbrt(x) = 1/(3 cbrt(x)^2). At x == 0 (or where the square underflows): 0.
    "math.cbrt": lambda ctx, x, r, g: _over(ctx, g, scale(ctx, ctx.mul(r, r), 3.0)),
    # d exp(x) = exp(x). Smooth everywhere.
    "math.exp": lambda ctx, x, r, g: ctx.mul(g, r),
    # d 2^x = 2^x ln 2. Smooth everywhere.
    "math.exp2": lambda ctx, x, r, g: scale(ctx, ctx.mul(g, r), math.log(2.0)),
    # d log_k(x) = 1/(x ln k). At x == 0: 0.
    "math.log": lambda ctx, x, r, g: _over(ctx, g, x),
    "math.log2": lambda ctx, x, r, g: _over(ctx, g, scale(ctx, x, math.log(2.0))),
    "math.log10": lambda ctx, x, r, g: _over(ctx, g, scale(ctx, x, math.log(10.0))),
    # d sin(x) = cos(x). Smooth everywhere.
    "math.sin": lambda ctx, x, r, g: ctx.mul(g, ctx.emit("math.cos", x)),
    # d cos(x) = -sin(x). Smooth everywhere.
    "math.cos": lambda ctx, x, r, g: ctx.neg(ctx.mul(g, ctx.emit("math.sin", x))),
    # d tan(x) = 1 + tan(x)^2. Finite wherever tan is (the poles are not representable).
    "math.tan": lambda ctx, x, r, g: ctx.mul(g, ctx.add(ctx.const(1, r.type), ctx.mul(r, r))),
    # d asin(x) = 1/sqrt(1 - x^2). At |x| >= 1: 0.
    "math.asin": lambda ctx, x, r, g: _arcsin_slope(ctx, x, g, 1.0),
    # d acos(x) = -1/sqrt(1 - x^2). At |x| >= 1: 0.
    "math.acos": lambda ctx, x, r, g: _arcsin_slope(ctx, x, g, -1.0),
    # d atan(x) = 1/(1 + x^2). Smooth everywhere.
    "math.atan": lambda ctx, x, r, g: ctx.div(g, ctx.add(ctx.const(1, x.type), ctx.mul(x, x))),
    # d sinh(x) = cosh(x). Smooth everywhere.
    "math.sinh": lambda ctx, x, r, g: ctx.mul(g, ctx.emit("math.cosh", x)),
    # d cosh(x) = sinh(x). Smooth everywhere.
    "math.cosh": lambda ctx, x, r, g: ctx.mul(g, ctx.emit("math.sinh", x)),
    # d tanh(x) = 1 - tanh(x)^2. Smooth everywhere.
    "math.tanh": lambda ctx, x, r, g: ctx.mul(g, ctx.sub(ctx.const(1, r.type), ctx.mul(r, r))),
    # d erf(x) = 2/sqrt(pi) exp(-x^2). Smooth everywhere.
    "math.erf": lambda ctx, x, r, g: _gauss(ctx, x, g, 2.0 / math.sqrt(math.pi)),
    # d erfc(x) = -2/sqrt(pi) exp(-x^2). Smooth everywhere.
    "math.erfc": lambda ctx, x, r, g: _gauss(ctx, x, g, -2.0 / math.sqrt(math.pi)),
    # d |x| = sign(x). At x == 0 (either sign of zero): +1, since math.sign is +1 at
    # both zeros: exactly the documented subgradient.
    "math.abs": lambda ctx, x, r, g: ctx.mul(g, ctx.emit("math.sign", x)),
}
for _name, _adjoint in _UNARY.items():
    rule(_name)(_unary(_adjoint))


@rule("math.floor", "math.ceil", "math.trunc", "math.round", "math.rint", "math.sign")
def _piecewise_constant(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """Piecewise constant: 0 everywhere, also at the jumps."""
    return [None]


@rule("math.copysign")
def _copysign(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """copysign(a, b) = |a| sgn(b): sgn(a) sgn(b) for a, 0 for b. sgn reads the sign bit,
    as Warp does: at a == +0 that is +sgn(b), at a == -0 -sgn(b)."""
    (g,) = adj
    a, b = ctx.operands(op)
    sgn_a = ctx.emit("math.copysign", ctx.const(1, a.type), a)
    sgn_b = ctx.emit("math.copysign", ctx.const(1, b.type), b)
    return [ctx.mul(g, ctx.mul(sgn_a, sgn_b)), None]


@rule("math.atan2")
def _atan2(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """atan2(y, x): x/(x^2+y^2) for y, -y/(x^2+y^2) for x. At x == y == 0: 0 for both."""
    (g,) = adj
    y, x = ctx.operands(op)
    r2 = ctx.add(ctx.mul(x, x), ctx.mul(y, y))
    scaled = _over(ctx, g, r2)
    return [ctx.mul(scaled, x), ctx.neg(ctx.mul(scaled, y))]
