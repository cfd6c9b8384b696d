"""Vector-Jacobian products: the interface between the op catalog and autodiff.

Each differentiable op carries a VJP rule in its catalog entry
(``OpDef.rules["vjp"]``), attached with ``@vjp_rule("math.sin")``. The adjoint pass
(``kdsl.passes.adjoint``) calls a rule during the reverse sweep::

    rule(ctx: VjpContext, op: Operation, adj: list[Value | None]) -> list[Value | None]

- ``op`` is the op of the *forward* function; ``ctx.primal(v)`` gives the value in
  the adjoint function that holds the forward value ``v`` (an operand or a result of
  ``op``). Never use ``op.operands`` directly in emitted ops.
- ``adj[i]`` is the adjoint of result ``i`` (None: zero; the pass calls a rule only
  when at least one is not None). Its type is the result's type.
- The rule returns one entry per operand: the adjoint *contribution* to that
  operand (same type as the operand), or None for zero or not differentiable
  (integers, bools, indices, conditions). The pass sums contributions.
- New ops go through ``ctx`` helpers; they land at the reverse sweep's insertion
  point stamped with ``op``'s source location.

Non-smooth and singular points (documented in ``docs/autodiff.md``): where an op's
derivative is infinite or undefined (``sqrt`` at 0, ``length``/``normalize`` of a
zero vector, ``acos``/``asin`` at +-1, ``pow`` at 0, ``atan2`` at the origin) the
rule gives 0 for that operand instead of inf or NaN; at kinks it uses the
subgradient documented with the rule (``abs`` at 0 gives +1, ``min``/``max`` ties
go to the first operand, rounding functions give 0).

Rules live in ``kdsl.ir.vjp_rules_*`` modules, loaded by ``load_rules()`` when the
first adjoint is built, so a scene without gradients never imports them.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Sequence
from typing import Any

from kdsl.ir.builder import Builder
from kdsl.ir.catalog import CATALOG
from kdsl.ir.core import Operation, Value
from kdsl.ir.types import (
    BOOL,
    ArrayType,
    MatrixType,
    ScalarType,
    StructType,
    Type,
    VectorType,
)

VjpRule = Callable[["VjpContext", Operation, Sequence["Value | None"]], Sequence["Value | None"]]

#: Modules holding VJP rules (each attaches its rules with ``@vjp_rule`` on import).
RULE_MODULES = (
    "kdsl.ir.vjp_rules_arith",
    "kdsl.ir.vjp_rules_math",
    "kdsl.ir.vjp_rules_vec",
)

_loaded = False


def vjp_rule(*names: str) -> Callable[[VjpRule], VjpRule]:
    """Attach the decorated function as the VJP rule of the catalog ops ``names``."""

    def deco(fn: VjpRule) -> VjpRule:
        for name in names:
            CATALOG.add_rule(name, "vjp", fn)
        return fn

    return deco


def load_rules() -> None:
    """Import every rule module once (idempotent)."""
    global _loaded
    if _loaded:
        return
    for name in RULE_MODULES:
        try:
            importlib.import_module(name)
        except ModuleNotFoundError as e:  # a rule module not written yet
            if e.name != name:
                raise
    _loaded = True


def get_rule(name: str) -> VjpRule | None:
    """The VJP rule of op ``name``, or None when it has none."""
    load_rules()
    return CATALOG[name].rules.get("vjp")


def is_differentiable(t: Type) -> bool:
    """True for types that carry adjoints: floats, float vectors/matrices, structs of them."""
    if isinstance(t, ScalarType):
        return t.is_float
    if isinstance(t, VectorType | MatrixType):
        return t.elem.is_float
    if isinstance(t, StructType):
        return any(is_differentiable(ft) for _, ft in t.fields)
    return False


class VjpContext:
    """What a VJP rule may use: forward values and op-emitting helpers.

    Every helper emits at the builder's insertion point with the builder's current
    location. Binary helpers follow the ``arith`` type rules (same types, or a scalar
    and a vector/matrix of it for ``mul``/``div``).
    """

    def __init__(self, builder: Builder, primal: Callable[[Value], Value]) -> None:
        self.b = builder
        self._primal = primal

    # -- forward values ------------------------------------------------------------
    def primal(self, v: Value) -> Value:
        """The adjoint function's copy of the forward value ``v``."""
        return self._primal(v)

    def operands(self, op: Operation) -> list[Value]:
        """``[self.primal(x) for x in op.operands]``."""
        return [self._primal(x) for x in op.operands]

    # -- emitting ------------------------------------------------------------------
    def emit(self, name: str, *operands: Value, **attrs: Any) -> Value:
        """A single-result op whose type comes from its type rule."""
        return self.b.value(name, *operands, **attrs)

    def emit_typed(self, name: str, operands: Sequence[Value], result: Type, **attrs: Any) -> Value:
        """A single-result op with an explicit result type (casts, constructors)."""
        return self.b.create(name, operands, [result], attrs or None).result

    def const(self, x: float | int | bool, t: Type) -> Value:
        """The constant ``x`` as a value of ``t`` (splatted for vectors and matrices)."""
        if isinstance(t, ScalarType):
            return self.b.constant(x, t)
        if isinstance(t, VectorType | MatrixType):
            return self.emit_typed("vec.splat", [self.b.constant(x, t.elem)], t)
        if isinstance(t, StructType):
            fields = [self.const(x if is_differentiable(ft) else 0, ft) for _, ft in t.fields]
            return self.emit_typed("struct.construct", fields, t)
        if isinstance(t, ArrayType):  # a struct adjoint's array field: never read
            return self.emit_typed("kd.null_array", [], t)
        raise TypeError(f"no constant of type {t}")

    def zeros(self, t: Type) -> Value:
        """The zero of ``t``."""
        return self.const(False if t == BOOL else 0, t)

    def add(self, a: Value, b: Value) -> Value:
        return self.emit("arith.add", a, b)

    def sub(self, a: Value, b: Value) -> Value:
        return self.emit("arith.sub", a, b)

    def mul(self, a: Value, b: Value) -> Value:
        return self.emit("arith.mul", a, b)

    def div(self, a: Value, b: Value) -> Value:
        return self.emit("arith.div", a, b)

    def neg(self, a: Value) -> Value:
        return self.emit("arith.neg", a)

    def select(self, cond: Value, a: Value, b: Value) -> Value:
        """``a`` if ``cond`` else ``b``."""
        return self.emit("arith.select", cond, a, b)

    def cmp(self, pred: str, a: Value, b: Value) -> Value:
        """A bool: ``a <pred> b`` with ``pred`` in eq, ne, lt, le, gt, ge."""
        return self.emit("arith.cmp", a, b, pred=pred)

    def extract(self, v: Value, *index: int) -> Value:
        """Component (vector), row or element (matrix) at constant indices."""
        from kdsl.ir.types import I32

        return self.emit("vec.extract", v, *[self.b.constant(i, I32) for i in index])

    def insert(self, v: Value, x: Value, *index: int) -> Value:
        """``v`` with the component/row at constant indices replaced by ``x``."""
        from kdsl.ir.types import I32

        return self.emit("vec.insert", v, x, *[self.b.constant(i, I32) for i in index])

    def sum(self, a: Value | None, b: Value | None) -> Value | None:
        """``a + b`` where None is zero."""
        if a is None:
            return b
        if b is None:
            return a
        return self.add(a, b)


__all__ = [
    "RULE_MODULES", "VjpContext", "VjpRule", "get_rule", "is_differentiable", "load_rules",
    "vjp_rule",
]  # fmt: skip
