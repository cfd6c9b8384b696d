"""Building blocks shared by the VJP rule modules (``kdsl.ir.vjp_rules_*``).

- ``rule``: ``vjp_rule`` plus the bookkeeping every rule would repeat (an op with
  no differentiable result gets no adjoints; operands that cannot carry adjoints,
  such as indices and conditions, always get None).
- ``where``: a componentwise, branch-free select. ``arith.cmp`` and ``arith.select``
  work on whole values (a vector comparison gives one bool), so a guard that must
  act per component (``sqrt`` of a vector with one zero component) splits the
  vector or matrix into scalars, selects each, and rebuilds it.
- ``zero_where_zero``: the usual guard, 0 where a denominator (or divisor) is 0.
- ``sum_product``: the sum over components of ``x * y``, the adjoint of a scalar
  that was broadcast against a vector or matrix.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence

from kdsl.ir.core import Operation, Value
from kdsl.ir.types import MatrixType, ScalarType, Type, VectorType, elem_type
from kdsl.ir.vjp import VjpContext, VjpRule, is_differentiable, vjp_rule


def rule(*names: str) -> Callable[[VjpRule], VjpRule]:
    """``vjp_rule(*names)`` that also drops adjoints no operand can take.

    The wrapped rule is called only when some result is differentiable; what it
    returns for a non-differentiable operand (an index, a bool) is replaced by None.
    """

    def deco(fn: VjpRule) -> VjpRule:
        @functools.wraps(fn)
        def wrapped(
            ctx: VjpContext, op: Operation, adj: Sequence[Value | None]
        ) -> list[Value | None]:
            if not any(is_differentiable(r.type) for r in op.results):
                return [None] * len(op.operands)
            out = list(fn(ctx, op, adj))
            if len(out) != len(op.operands):
                raise AssertionError(
                    f"VJP rule of {op.name} gave {len(out)} adjoints "
                    f"for {len(op.operands)} operands"
                )
            return [c if is_differentiable(x.type) else None for x, c in zip(op.operands, out)]

        vjp_rule(*names)(wrapped)
        return wrapped

    return deco


def components(ctx: VjpContext, v: Value) -> list[Value]:
    """The scalar components of ``v`` in row-major order (``[v]`` for a scalar)."""
    t = v.type
    if isinstance(t, MatrixType):
        return [ctx.extract(v, i, j) for i in range(t.rows) for j in range(t.cols)]
    if isinstance(t, VectorType):
        return [ctx.extract(v, i) for i in range(t.length)]
    return [v]


def assemble(ctx: VjpContext, parts: Sequence[Value], t: Type) -> Value:
    """The value of type ``t`` whose row-major components are ``parts``."""
    if isinstance(t, ScalarType):
        (only,) = parts
        return only
    return ctx.emit_typed("vec.construct", parts, t)


def where(
    ctx: VjpContext,
    cond: Callable[..., Value],
    args: Sequence[Value],
    a: Value | None,
    b: Value | None,
) -> Value:
    """Componentwise ``a if cond(*args) else b``; None stands for zero.

    ``cond`` receives the scalar components of ``args`` (all of one shape as ``a``
    and ``b``) and emits a bool. Branch-free: both choices are computed.
    """
    t = (a if a is not None else b).type  # type: ignore[union-attr]
    if isinstance(t, ScalarType):
        zero = ctx.zeros(t)
        return ctx.select(cond(*args), zero if a is None else a, zero if b is None else b)
    zero = ctx.zeros(elem_type(t))
    cols = [components(ctx, x) for x in args]
    ca = components(ctx, a) if a is not None else None
    cb = components(ctx, b) if b is not None else None
    parts = []
    for k in range(len(cols[0])):
        c = cond(*(col[k] for col in cols))
        parts.append(ctx.select(c, zero if ca is None else ca[k], zero if cb is None else cb[k]))
    return assemble(ctx, parts, t)


def zero_where_zero(ctx: VjpContext, guard: Value, value: Value) -> Value:
    """Componentwise ``0 if guard == 0 else value`` (``guard`` has ``value``'s type)."""
    zero = ctx.zeros(elem_type(guard.type))
    return where(ctx, lambda g: ctx.cmp("eq", g, zero), [guard], None, value)


def sum_product(ctx: VjpContext, x: Value, y: Value) -> Value:
    """The scalar ``sum(x * y)`` over all components of two values of one type."""
    t = x.type
    if isinstance(t, MatrixType):
        total = None
        for i in range(t.rows):
            total = ctx.sum(total, ctx.emit("vec.dot", ctx.extract(x, i), ctx.extract(y, i)))
        return total  # type: ignore[return-value]
    if isinstance(t, VectorType):
        return ctx.emit("vec.dot", x, y)
    return ctx.mul(x, y)


def scalar_const(ctx: VjpContext, x: float, t: Type) -> Value:
    """The constant ``x`` of ``t``'s element type (for scaling a vector or matrix)."""
    return ctx.const(x, elem_type(t))


def scale(ctx: VjpContext, v: Value, x: float) -> Value:
    """``v * x`` for a Python number ``x``, at ``v``'s element type."""
    return ctx.mul(v, scalar_const(ctx, x, v.type))


__all__ = [
    "assemble", "components", "rule", "scalar_const", "scale", "sum_product", "where",
    "zero_where_zero",
]  # fmt: skip
