"""Rewriting helpers shared by the passes: effects, constants, cloning, inlining regions.

IR-generic (they read op traits, never a pass's own tables), so they live with the
IR rather than among the passes; ``kdsl.ir.rewrite_scf`` adds the rewrites of
structured ops that drop unneeded values.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence
from typing import Any

from kdsl.ir.builder import normalize_constant
from kdsl.ir.catalog import (
    CATALOG,
    CONSTANT_LIKE,
    PURE,
    READS,
    RECURSIVE_EFFECTS,
    SPECULATABLE,
    WRITES,
)
from kdsl.ir.core import Block, Module, Operation, OpResult, Region, Value
from kdsl.ir.types import ScalarType


def constant_of(v: Value) -> tuple[bool, Any]:
    """``(True, value)`` if ``v`` is the result of a constant-like op (``arith.constant``)."""
    if isinstance(v, OpResult) and CONSTANT_LIKE in v.op.opdef.traits:
        return True, v.op.attrs["value"]
    return False, None


def is_constant_equal(v: Value, want: float, *, sign: bool = False) -> bool:
    """True if ``v`` is a constant equal to ``want`` (and of ``want``'s sign if asked)."""
    ok, c = constant_of(v)
    if not ok or isinstance(c, bool) != isinstance(want, bool):
        return False
    if c != want:
        return False
    return not sign or math.copysign(1.0, c) == math.copysign(1.0, want)


def has_trait(op: Operation, trait: str) -> bool:
    """True if ``op``'s catalog entry carries ``trait`` (``PURE``, ``WRITES``, ...)."""
    return trait in op.opdef.traits


def is_speculatable(op: Operation) -> bool:
    """True if ``op`` may run on a path that did not ask for it (no regions, no effects)."""
    return has_trait(op, SPECULATABLE) and not op.regions


def may_write(op: Operation) -> bool:
    """True if ``op`` or anything nested in it may write memory or has unknown effects."""
    for inner in op.walk():
        traits = inner.opdef.traits
        if WRITES in traits:
            return True
        known = PURE in traits or READS in traits or inner.opdef.is_terminator
        if not known and RECURSIVE_EFFECTS not in traits:
            return True  # e.g. func.call: unknown effects
    return False


def is_trivially_dead(op: Operation) -> bool:
    """MLIR's ``wouldOpBeTriviallyDead``: unused results and no effect but reads."""
    if op.opdef.is_terminator or any(r.uses for r in op.results):
        return False
    if op.regions and not has_trait(op, RECURSIVE_EFFECTS):
        return False
    return not may_write(op)


def replace_op(op: Operation, values: Sequence[Value]) -> None:
    """Replace every result of ``op`` with ``values`` and erase ``op``."""
    for r, v in zip(op.results, values):
        r.replace_all_uses_with(v)
    op.erase()


def insert_before(anchor: Operation, op: Operation) -> Operation:
    """Insert the unattached ``op`` right before ``anchor``; return ``op``."""
    assert anchor.parent is not None
    return anchor.parent.insert_before(anchor, op)


def make_constant(value: Any, type: ScalarType, anchor: Operation) -> Value:
    """An ``arith.constant`` of ``value`` inserted before ``anchor``."""
    value = normalize_constant(value, type)
    op = Operation(CATALOG["arith.constant"], (), [type], {"value": value}, (), anchor.loc)
    return insert_before(anchor, op).result


def inline_block_before(block: Block, anchor: Operation, args: Sequence[Value]) -> list[Value]:
    """Move ``block``'s ops before ``anchor``, its arguments replaced by ``args``.

    Returns the operands of the block's terminator, which is dropped.
    """
    for a, v in zip(block.args, args):
        a.replace_all_uses_with(v)
    term = block.ops[-1]
    yielded = list(term.operands)
    term.drop_operands()
    block.detach(term)
    parent = anchor.parent
    assert parent is not None
    for op in list(block.ops):
        block.detach(op)
        parent.insert_before(anchor, op)
    return yielded


def clone_op(op: Operation, mapping: dict[Value, Value]) -> Operation:
    """A deep copy of ``op``; operands are looked up in ``mapping``, which it extends."""
    regions = [Region(clone_block(r.block, mapping)) for r in op.regions]
    new = Operation(
        op.opdef,
        [mapping.get(v, v) for v in op.operands],
        [r.type for r in op.results],
        copy_attr(op.attrs),
        regions,
        op.loc,
    )
    for old_r, new_r in zip(op.results, new.results):
        new_r.name_hint = old_r.name_hint
        mapping[old_r] = new_r
    return new


def clone_block(block: Block, mapping: dict[Value, Value]) -> Block:
    """A deep copy of ``block`` (see ``clone_op``); ``mapping`` gains its values."""
    new = Block([a.type for a in block.args], [a.name_hint for a in block.args])
    for old_a, new_a in zip(block.args, new.args):
        mapping[old_a] = new_a
    for op in block.ops:
        new.append(clone_op(op, mapping))
    return new


def copy_attr(value: Any) -> Any:
    """A copy of an attribute value: nested dicts and lists copied, the rest shared."""
    if isinstance(value, dict):
        return {k: copy_attr(v) for k, v in value.items()}
    if isinstance(value, list):
        return [copy_attr(v) for v in value]
    return value


def rebuild_with_results(
    op: Operation, keep: Sequence[int], operands: Sequence[Value]
) -> Operation:
    """Replace ``op`` by a copy with only results ``keep`` and the given operands.

    The regions move to the new op unchanged; uses of kept results are redirected.
    Dropped results must be unused.
    """
    regions = list(op.regions)
    new = Operation(op.opdef, operands, [op.results[i].type for i in keep], op.attrs, (), op.loc)
    for r in regions:
        new.add_region(r)
    op.regions = []
    insert_before(op, new)
    for j, i in enumerate(keep):
        new.results[j].name_hint = op.results[i].name_hint
        op.results[i].replace_all_uses_with(new.results[j])
    op.erase()
    return new


def walk_blocks(module: Module) -> Iterator[Block]:
    """Every block of every function, outer blocks before the blocks nested in them."""
    for func in module.funcs:
        yield from _blocks_of(func)


def _blocks_of(op: Operation) -> Iterator[Block]:
    for region in op.regions:
        yield region.block
        for inner in list(region.block.ops):
            yield from _blocks_of(inner)


def rewrite_postorder(block: Block, visit: Callable[[Operation], bool]) -> bool:
    """Call ``visit`` on every op under ``block``, nested ops before their parent.

    ``visit`` may erase or replace the op it is given (and ops before it).
    """
    changed = False
    for op in list(block.ops):
        if op.parent is not block:
            continue  # erased or moved by an earlier rewrite
        for region in list(op.regions):
            changed |= rewrite_postorder(region.block, visit)
        if op.parent is block:
            changed |= visit(op)
    return changed


def rewrite_module(module: Module, visit: Callable[[Operation], bool], rounds: int = 1) -> bool:
    """``rewrite_postorder`` over the body of every function.

    Repeated while a round changes something, ``rounds`` times at most.
    """
    changed = False
    for _ in range(rounds):
        round_changed = False
        for func in module.funcs:
            round_changed |= rewrite_postorder(func.regions[0].block, visit)
        if not round_changed:
            break
        changed = True
    return changed
