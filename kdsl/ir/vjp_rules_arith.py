"""VJP rules of the ``arith`` dialect (see ``kdsl.ir.vjp`` for the interface).

Each rule's docstring gives its derivative and, in one line, its policy at
non-smooth or singular points. Rules are type-generic: they work on scalars,
vectors and matrices alike, and on the scalar-times-composite forms of ``mul`` and
``div``. Integer and bool operands never get adjoints.
"""

from __future__ import annotations

from collections.abc import Sequence

from kdsl.ir.core import Operation, Value
from kdsl.ir.types import elem_type
from kdsl.ir.vjp import VjpContext, is_differentiable
from kdsl.ir.vjp_helpers import rule, sum_product, where, zero_where_zero

Adj = Sequence["Value | None"]


@rule("arith.constant")
def _constant(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """No operands, so nothing to give."""
    return []


@rule("arith.add")
def _add(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """d(a+b) = da + db. Smooth everywhere."""
    (g,) = adj
    return [g, g]


@rule("arith.sub")
def _sub(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """d(a-b) = da - db. Smooth everywhere."""
    (g,) = adj
    return [g, ctx.neg(g)]


@rule("arith.neg")
def _neg(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """d(-a) = -da. Smooth everywhere."""
    (g,) = adj
    return [ctx.neg(g)]


def _scaled(ctx: VjpContext, x: Value, g: Value, other: Value) -> Value:
    """Adjoint of ``x`` in ``x * other`` given the result's adjoint ``g``.

    When ``x`` is a scalar that scaled a vector or matrix, its adjoint is the sum
    over components of ``g * other``.
    """
    if x.type == g.type:
        return ctx.mul(g, other)
    return sum_product(ctx, g, other)


@rule("arith.mul")
def _mul(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """d(a*b) = b da + a db (elementwise; a scaling scalar sums its components). Smooth."""
    (g,) = adj
    a, b = ctx.operands(op)
    return [_scaled(ctx, a, g, b), _scaled(ctx, b, g, a)]


@rule("arith.div")
def _div(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """d(a/b) = da/b - (a/b) db/b. At b == 0 the adjoints are inf/NaN, like the quotient."""
    (g,) = adj
    a, b = ctx.operands(op)
    r = ctx.primal(op.results[0])
    g_over_b = ctx.div(g, b)
    adj_a = g_over_b if a.type == g.type else sum_product(ctx, g_over_b, ctx.const(1, g.type))
    # -g * r / b, summed over components when b is a scalar that divided a composite.
    if b.type == g.type:
        adj_b = ctx.neg(ctx.mul(g_over_b, r))
    else:
        adj_b = ctx.neg(ctx.div(sum_product(ctx, g, r), b))
    return [adj_a, adj_b]


def _pick_returned(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """Adjoints of ``min``/``max``, per component, as Warp's ``adj_min``/``adj_max``.

    ``a`` gets the adjoint where the result is ``a`` and not also ``b`` (so ``a`` won
    strictly, or ``b`` is NaN); ``b`` gets it everywhere else: at ties (``-0`` and
    ``+0`` included) and where ``a`` is NaN.
    """
    (g,) = adj
    a, b = ctx.operands(op)
    r = ctx.primal(op.results[0])

    def a_won(ra: Value, aa: Value, bb: Value) -> Value:
        return ctx.emit("arith.and", ctx.cmp("eq", ra, aa), ctx.cmp("ne", ra, bb))

    return [where(ctx, a_won, [r, a, b], g, None), where(ctx, a_won, [r, a, b], None, g)]


@rule("arith.min")
def _min(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """The smaller operand gets the adjoint. Ties: the second operand (Warp's choice); NaN:
    the operand returned."""
    return _pick_returned(ctx, op, adj)


@rule("arith.max")
def _max(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """The larger operand gets the adjoint. Ties: the second operand (Warp's choice); NaN:
    the operand returned."""
    return _pick_returned(ctx, op, adj)


@rule("arith.mod")
def _mod(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """fmod(a, b) = a - trunc(a/b) b: da, -trunc(a/b) db. Jumps: one-sided; b == 0: 0 for b."""
    (g,) = adj
    a, b = ctx.operands(op)
    quot = ctx.emit("math.trunc", ctx.div(a, b))
    adj_b = zero_where_zero(ctx, b, ctx.neg(ctx.mul(g, quot)))
    return [g, adj_b]


@rule("arith.floordiv")
def _floordiv(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """floor(a/b) is piecewise constant: 0 for both operands (also at the jumps)."""
    return [None, None]


@rule("arith.pow")
def _pow(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """da: b a^(b-1), db: a^b log(a). a == 0 and b < 1: 0 for a; a <= 0: 0 for b."""
    (g,) = adj
    a, b = ctx.operands(op)
    r = ctx.primal(op.results[0])
    t = a.type
    one = ctx.const(1, t)
    da = ctx.mul(g, ctx.mul(b, ctx.emit("arith.pow", a, ctx.sub(b, one))))
    db = ctx.mul(g, ctx.mul(r, ctx.emit("math.log", a)))
    et = elem_type(t)
    zero, one_s = ctx.zeros(et), ctx.const(1, et)

    def a_singular(aa: Value, bb: Value) -> Value:
        return ctx.emit("arith.and", ctx.cmp("eq", aa, zero), ctx.cmp("lt", bb, one_s))

    adj_a = where(ctx, a_singular, [a, b], None, da)
    adj_b = where(ctx, lambda aa: ctx.cmp("le", aa, zero), [a], None, db)
    return [adj_a, adj_b]


@rule("arith.select")
def _select(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """The chosen operand gets the adjoint; the condition gets none."""
    (g,) = adj
    c = ctx.primal(op.operands[0])
    zero = ctx.zeros(g.type)
    return [None, ctx.select(c, g, zero), ctx.select(c, zero, g)]


@rule("arith.cast")
def _cast(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """Float to float: the adjoint cast back. Integer or bool sources get none."""
    (g,) = adj
    src = op.operands[0].type
    if not is_differentiable(src):
        return [None]
    return [ctx.emit_typed("arith.cast", [g], src)]


@rule("arith.bitcast")
def _bitcast(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """Reinterpreted bits are not a differentiable function of the value: none (as Warp's
    ``cast``, which has no adjoint)."""
    return [None]
