"""Local simplifications that are exact in IEEE arithmetic and for wrapping integers.

Patterns (dispatched by op definition from one table, or by trait):

- constants move to the right of ``commutative`` ops;
- ``x * 1 -> x``; ``x + 0 -> x`` for integers only (for floats ``-0.0 + 0.0`` is
  ``+0.0``), but ``x + (-0.0) -> x`` and ``x - 0.0 -> x`` for floats too (both
  exact, signed zeros included);
- ``f(f x) -> x`` for ``involution`` ops (``neg``, ``not``), a cast to the operand's
  own type;
- ``select(c, x, x) -> x``; on bools ``select(c, x, false) -> and(c, x)``,
  ``select(c, true, x) -> or(c, x)``, ``select(c, true, false) -> c``;
- ``cmp(x, x)`` on integers and bools gives its constant answer (not on floats: NaN);
- ``vec.extract`` of a ``vec.construct``/``vec.insert`` at constant indices and
  ``struct.extract`` of ``struct.construct``/``struct.insert`` give the component;
- an ``scf.if`` yielding one value in both branches gives it directly; unused
  ``scf.if`` results are dropped; an ``scf.if`` whose regions hold only
  speculatable ops (at most ``speculate_limit`` of them) becomes ``arith.select``
  (how the frontend's short-circuit ``and``/``or`` turns into plain logic);
- loop-carried values of ``scf.for``/``scf.while`` that nothing needs are removed.

Never reassociates floats. Options: ``max_iters`` (rounds), ``speculate_limit``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar

from kdsl.ir import Module, Operation, Value
from kdsl.ir.catalog import COMMUTATIVE, INVOLUTION, OpDef
from kdsl.ir.core import OpResult
from kdsl.ir.ops_arith import ADD, AND, CAST, CMP, MUL, OR, SELECT, SUB
from kdsl.ir.ops_scf import FOR, IF, WHILE
from kdsl.ir.ops_vec import (
    CONSTRUCT,
    EXTRACT,
    INSERT,
    STRUCT_CONSTRUCT,
    STRUCT_EXTRACT,
    STRUCT_INSERT,
)
from kdsl.ir.rewrite import (
    constant_of,
    inline_block_before,
    insert_before,
    is_constant_equal,
    is_speculatable,
    make_constant,
    replace_op,
    rewrite_module,
)
from kdsl.ir.rewrite_scf import (
    drop_dead_for_values,
    drop_dead_while_values,
    drop_unused_if_results,
)
from kdsl.ir.types import BOOL, MatrixType, ScalarType, VectorType, elem_type, value_shape
from kdsl.passes.manager import ModulePass

Pattern = Callable[[Operation], bool]


def _replace(op: Operation, v: Value) -> bool:
    replace_op(op, [v])
    return True


def _is_float(v: Value) -> bool:
    return elem_type(v.type).is_float


def _swap_constant_left(op: Operation) -> bool:
    lhs, rhs = op.operands
    if constant_of(lhs)[0] and not constant_of(rhs)[0]:
        op.set_operands([rhs, lhs])
        return True
    return False


def _same_type_operand(op: Operation) -> Value:
    return op.operands[0]


def _add(op: Operation) -> bool:
    x, c = op.operands
    if x.type != op.result.type:
        return False
    if _is_float(x):
        return is_constant_equal(c, -0.0, sign=True) and _replace(op, x)
    return is_constant_equal(c, 0) and _replace(op, x)


def _sub(op: Operation) -> bool:
    x, c = op.operands
    zero = 0.0 if _is_float(x) else 0
    return x.type == op.result.type and is_constant_equal(c, zero, sign=True) and _replace(op, x)


def _mul(op: Operation) -> bool:
    x, c = op.operands
    one = 1.0 if _is_float(x) else 1
    return x.type == op.result.type and is_constant_equal(c, one) and _replace(op, x)


def _involution(op: Operation) -> bool:
    (x,) = op.operands
    if isinstance(x, OpResult) and x.op.opdef is op.opdef:
        return _replace(op, x.op.operands[0])
    return False


def _cast(op: Operation) -> bool:
    x = op.operands[0]
    return x.type == op.result.type and _replace(op, x)


def _new_value(anchor: Operation, opdef: OpDef, *operands: Value) -> Value:
    new = Operation(opdef, operands, [operands[-1].type], None, (), anchor.loc)
    return insert_before(anchor, new).result


def _select(op: Operation) -> bool:
    c, a, b = op.operands
    if a is b:
        return _replace(op, a)
    if op.result.type != BOOL:
        return False
    ok_a, ca = constant_of(a)
    ok_b, cb = constant_of(b)
    if ok_a and ok_b and ca is True and cb is False:
        return _replace(op, c)
    if ok_b and cb is False:
        return _replace(op, _new_value(op, AND, c, a))
    if ok_a and ca is True:
        return _replace(op, _new_value(op, OR, c, b))
    return False


_SELF_CMP = {"eq": True, "le": True, "ge": True, "ne": False, "lt": False, "gt": False}


def _cmp(op: Operation) -> bool:
    a, b = op.operands
    et = elem_type(a.type)
    if a is not b or et.is_float:
        return False
    return _replace(op, make_constant(_SELF_CMP[op.attrs["pred"]], BOOL, op))


def _const_indices(values: list[Value]) -> tuple[int, ...] | None:
    out = []
    for v in values:
        ok, c = constant_of(v)
        if not ok:
            return None
        out.append(int(c))
    return tuple(out)


def _in_range(t, idx: tuple[int, ...]) -> bool:
    return all(0 <= i < n for i, n in zip(idx, value_shape(t)))


def _component_of_construct(src: Operation, t, idx: tuple[int, ...]) -> Value | None:
    parts = src.operands
    if all(isinstance(p.type, ScalarType) for p in parts):
        if isinstance(t, MatrixType) and len(idx) == 2:
            return parts[idx[0] * t.cols + idx[1]]
        if isinstance(t, VectorType) and not isinstance(t, MatrixType) and len(idx) == 1:
            return parts[idx[0]]
    rows = isinstance(t, MatrixType) and len(idx) == 1 and len(parts) == t.rows
    if rows and all(p.type == t.row_type for p in parts):
        return parts[idx[0]]
    return None


def _vec_extract(op: Operation) -> bool:
    v = op.operands[0]
    idx = _const_indices(op.operands[1:])
    if idx is None or not isinstance(v, OpResult) or not _in_range(v.type, idx):
        return False
    src = v.op
    if src.opdef is CONSTRUCT:
        part = _component_of_construct(src, v.type, idx)
        return part is not None and _replace(op, part)
    if src.opdef is INSERT and len(src.operands) - 2 == len(idx):
        at = _const_indices(src.operands[2:])
        if at == idx:
            return _replace(op, src.operands[1])
        if at is not None:
            op.set_operand(0, src.operands[0])  # a different component: look through
            return True
    return False


def _struct_extract(op: Operation) -> bool:
    s = op.operands[0]
    if not isinstance(s, OpResult):
        return False
    field = op.attrs["field"]
    if s.op.opdef is STRUCT_CONSTRUCT:
        return _replace(op, s.op.operands[s.type.field_index(field)])
    if s.op.opdef is STRUCT_INSERT:
        if s.op.attrs["field"] == field:
            return _replace(op, s.op.operands[1])
        op.set_operand(0, s.op.operands[0])
        return True
    return False


def _if_same_yield(op: Operation) -> bool:
    then_y, else_y = (r.block.ops[-1].operands for r in op.regions)
    changed = False
    for r, a, b in zip(op.results, then_y, else_y):
        if a is b and r.uses:
            r.replace_all_uses_with(a)  # one value in both branches: defined outside
            changed = True
    return changed


def _if_to_select(op: Operation, limit: int) -> bool:
    bodies = [r.block.ops[:-1] for r in op.regions]
    if sum(len(b) for b in bodies) > limit:
        return False
    if not all(is_speculatable(o) for b in bodies for o in b):
        return False
    then_v = inline_block_before(op.regions[0].block, op, ())
    else_v = inline_block_before(op.regions[1].block, op, ())
    cond = op.operands[0]
    values = []
    for r, a, b in zip(op.results, then_v, else_v):
        if a is b:
            values.append(a)
            continue
        sel = Operation(SELECT, (cond, a, b), [r.type], None, (), op.loc)
        values.append(insert_before(op, sel).result)
    replace_op(op, values)
    return True


@dataclass(frozen=True)
class CanonicalizePass(ModulePass):
    """Exact algebraic simplifications (see the module docstring)."""

    name: ClassVar[str] = "canonicalize"
    #: Upper bound on rounds over the module.
    max_iters: int = 8
    #: Most ops an ``scf.if`` may hold (both branches) to become ``arith.select``.
    speculate_limit: int = 8

    def _patterns(self) -> dict[OpDef, Pattern]:
        return {
            ADD: _add, SUB: _sub, MUL: _mul, CAST: _cast, SELECT: _select, CMP: _cmp,
            EXTRACT: _vec_extract, STRUCT_EXTRACT: _struct_extract,
            IF: self._scf_if, FOR: drop_dead_for_values, WHILE: drop_dead_while_values,
        }  # fmt: skip

    def _scf_if(self, op: Operation) -> bool:
        changed = _if_same_yield(op)
        if _if_to_select(op, self.speculate_limit):
            return True
        return drop_unused_if_results(op) or changed

    def apply(self, module: Module) -> bool:
        patterns = self._patterns()

        def visit(op: Operation) -> bool:
            changed = False
            traits = op.opdef.traits
            if COMMUTATIVE in traits and len(op.operands) == 2:
                changed = _swap_constant_left(op)
            rule = _involution if INVOLUTION in traits else patterns.get(op.opdef)
            return (rule is not None and rule(op)) or changed

        return rewrite_module(module, visit, rounds=self.max_iters)
