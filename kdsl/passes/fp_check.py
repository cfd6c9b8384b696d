"""Debug mode (``verify_fp``): a ``kd.check_finite`` before every store of a float value.

Each op that writes an operand's value into memory (its catalog entry names the
``stored_operand``: ``kd.store``, ``kd.atomic_rmw``) whose value is a float (or a
vector or matrix of floats) gets a ``kd.check_finite`` of that value right before it, with
the store's location, the array's name and a fresh ``site`` number, so the first
NaN or Inf that reaches memory names the source line that wrote it. Values that
stay in registers are not checked (an Inf in an intermediate may be intended).
Idempotent like ``bounds-check``; run it after optimization. No options.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from kdsl.ir import Module, Operation, Value
from kdsl.ir.ops_debug import CHECK_BOUNDS, CHECK_FINITE, CheckPlan, insert_checks
from kdsl.ir.types import MatrixType, ScalarType, Type, VectorType
from kdsl.passes.manager import ModulePass


def is_float_value(t: Type) -> bool:
    """True for float scalars and vectors or matrices of floats."""
    if isinstance(t, VectorType | MatrixType):
        t = t.elem
    return isinstance(t, ScalarType) and t.is_float


def _already_checked(op: Operation, value: Value) -> bool:
    block = op.parent
    pos = block.ops.index(op)
    # A bounds check may sit between the value's check and the store.
    for prev in reversed(block.ops[max(0, pos - 2) : pos]):
        if prev.opdef is CHECK_FINITE and prev.operands[0] is value:
            return True
        if prev.opdef is not CHECK_BOUNDS:
            return False
    return False


def _plan(op: Operation) -> CheckPlan | None:
    at = op.opdef.stored_operand
    if at is None or not is_float_value(op.operands[at].type):
        return None
    value = op.operands[at]
    if _already_checked(op, value):
        return None
    # Keep the bounds check right before its access (its idempotence test).
    pos = op.parent.ops.index(op)
    if pos > 0 and op.parent.ops[pos - 1].opdef is CHECK_BOUNDS:
        return [value], op.parent.ops[pos - 1]
    return [value], op


@dataclass(frozen=True)
class FpCheckPass(ModulePass):
    """Insert ``kd.check_finite`` before float stores (see the module docstring)."""

    name: ClassVar[str] = "fp-check"

    def apply(self, module: Module) -> bool:
        return insert_checks(module, CHECK_FINITE, _plan)
