"""Dead code elimination, driven by op traits (as xDSL's ``dead_code_elimination``).

An op is removed when it is *trivially dead*, following MLIR's
``wouldOpBeTriviallyDead``: none of its results is used and it has no effect other
than reading memory. That covers unused pure ops, unused loads, and ``scf.if`` /
``scf.for`` / ``scf.while`` ops whose results are unused and whose regions hold no
op that writes memory (``kd.store``, ``kd.atomic_rmw``) or has unknown effects
(``func.call``). Stores and atomics are never removed. It also drops unused results
of ``scf.if`` and loop-carried values that no one reads (see ``kdsl.ir.rewrite_scf``).

Blocks are scanned from the end so a chain of dead ops goes in one sweep; rounds
repeat until nothing changes. No options.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from kdsl.ir import Block, Module
from kdsl.ir.ops_scf import FOR, IF, WHILE
from kdsl.ir.rewrite import is_trivially_dead
from kdsl.ir.rewrite_scf import (
    drop_dead_for_values,
    drop_dead_while_values,
    drop_unused_if_results,
)
from kdsl.passes.manager import ModulePass

#: Region op -> what drops the values it carries or yields that nobody uses.
_TRIM = {
    IF: drop_unused_if_results,
    FOR: drop_dead_for_values,
    WHILE: drop_dead_while_values,
}


def _dce_block(block: Block) -> bool:
    changed = False
    for op in reversed(list(block.ops)):
        if op.parent is not block:
            continue
        if is_trivially_dead(op):
            op.erase()
            changed = True
            continue
        for region in op.regions:
            changed |= _dce_block(region.block)
        trim = _TRIM.get(op.opdef)
        if trim is not None:
            changed |= trim(op)
    return changed


@dataclass(frozen=True)
class DCEPass(ModulePass):
    """Dead code elimination (see the module docstring)."""

    name: ClassVar[str] = "dce"

    def apply(self, module: Module) -> bool:
        changed = False
        while True:
            round_changed = False
            for func in module.funcs:
                round_changed |= _dce_block(func.regions[0].block)
            if not round_changed:
                return changed
            changed = True
