"""Common subexpression elimination of pure ops, scoped by structured regions.

Two pure, region-free ops are the same expression when they have the same name,
operands (in any order for commutative ops), attributes and result types; the
later one is replaced by the earlier. A value computed in an outer block is
visible in the regions nested below it (structured dominance), but not in sibling
regions or outer blocks, so the table of known expressions is scoped per block,
as in MLIR's CSE with its scoped hash table.

Ops that read or write memory (``kd.load``, ``kd.store``, ``kd.atomic_rmw``) and
calls are never merged: a load after a store may read another value. Attribute
keys compare floats by their bits, so ``0.0`` and ``-0.0`` (and NaNs) stay apart.

No options.
"""

from __future__ import annotations

from collections import ChainMap
from dataclasses import dataclass
from typing import Any, ClassVar

from kdsl.ir import Block, Module, Operation
from kdsl.ir.catalog import COMMUTATIVE, PURE
from kdsl.passes.manager import ModulePass


def _attr_key(value: Any) -> Any:
    if isinstance(value, bool):
        return ("b", value)
    if isinstance(value, float):
        return ("f", value.hex())
    if isinstance(value, int):
        return ("i", value)
    if isinstance(value, list | tuple):
        return ("l", tuple(_attr_key(v) for v in value))
    try:
        hash(value)
    except TypeError:
        return ("r", repr(value))
    return ("o", type(value).__name__, value)


def expression_key(op: Operation) -> tuple | None:
    """A hashable key equal for ops that compute the same value; None if not CSE-able."""
    if PURE not in op.opdef.traits or op.regions or not op.results:
        return None
    ids = [id(v) for v in op.operands]
    if COMMUTATIVE in op.opdef.traits:
        ids.sort()
    attrs = tuple(sorted((k, _attr_key(v)) for k, v in op.attrs.items()))
    return (op.name, tuple(ids), attrs, tuple(r.type for r in op.results))


def _cse_block(block: Block, known: ChainMap) -> bool:
    changed = False
    for op in list(block.ops):
        key = expression_key(op)
        if key is not None:
            prev = known.get(key)
            if prev is not None:
                for old, new in zip(op.results, prev.results):
                    old.replace_all_uses_with(new)
                op.erase()
                changed = True
                continue
            known[key] = op
        for region in op.regions:
            changed |= _cse_block(region.block, known.new_child())
    return changed


@dataclass(frozen=True)
class CSEPass(ModulePass):
    """Common subexpression elimination (see the module docstring)."""

    name: ClassVar[str] = "cse"

    def apply(self, module: Module) -> bool:
        changed = False
        for func in module.funcs:
            changed |= _cse_block(func.regions[0].block, ChainMap())
        return changed
