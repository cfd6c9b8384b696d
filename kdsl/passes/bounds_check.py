"""Debug mode: a ``kd.check_bounds`` before every array access.

Every op that reaches an array element (one whose catalog entry names its
``array_operand``: ``kd.load``, ``kd.store``, ``kd.atomic_rmw``, ``kd.atomic_cas``),
and every ``kd.array_view`` (its leading indices), gets a ``kd.check_bounds`` of its
array and indices right before it, with the access's location, the array's name
(``arg``) and a fresh ``site`` number (see ``kdsl.ir.ops_debug``). A backend stops
the failing thread at the check, so the access never touches memory.

Run it after optimization: the checks then guard exactly the accesses that
remain, and nothing after it can remove them (they carry the WRITES trait). An
access the optimizer deleted (an unused load) is not checked: it never happens.
Accesses that already have their check right before them are skipped, so the
pass is idempotent. No options.

Every ``kd.record`` (a runtime object's record read from its id) likewise gets a
``kd.check_record`` of the id, so a null, freed or foreign id stops the thread with
an error instead of reading stray memory.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from kdsl.ir import Module, Operation
from kdsl.ir.ops_debug import CHECK_BOUNDS, CHECK_RECORD, CheckPlan, insert_checks
from kdsl.ir.records import RECORD
from kdsl.passes.manager import ModulePass


def _already_checked(op: Operation, operands: list) -> bool:
    block = op.parent
    pos = block.ops.index(op)
    prev = block.ops[pos - 1] if pos > 0 else None
    return prev is not None and prev.opdef is CHECK_BOUNDS and list(prev.operands) == operands


def _plan(op: Operation) -> CheckPlan | None:
    at = 0 if op.name == "kd.array_view" else op.opdef.array_operand
    if at is None:
        return None
    operands = list(op.operands[at:])
    if _already_checked(op, operands):
        return None
    return operands, op


@dataclass(frozen=True)
class BoundsCheckPass(ModulePass):
    """Insert ``kd.check_bounds`` before array accesses (see the module docstring)."""

    name: ClassVar[str] = "bounds-check"

    def apply(self, module: Module) -> bool:
        arrays = insert_checks(module, CHECK_BOUNDS, _plan)
        records = insert_checks(module, CHECK_RECORD, _plan_record, _record_name)
        return arrays or records


def _plan_record(op: Operation) -> CheckPlan | None:
    if op.opdef is not RECORD:
        return None
    block = op.parent
    pos = block.ops.index(op)
    prev = block.ops[pos - 1] if pos > 0 else None
    if prev is not None and prev.opdef is CHECK_RECORD and prev.operands[0] is op.operands[0]:
        return None
    return [op.operands[0]], op


def _record_name(op: Operation) -> str:
    return op.results[0].type.name
