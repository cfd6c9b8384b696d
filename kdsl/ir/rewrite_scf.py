"""Removing values that structured ops (``scf.if``, ``scf.for``, ``scf.while``) carry or
yield but nobody needs.

Shared by ``canonicalize`` and ``dce``, like the canonicalization patterns MLIR keeps
with its ``scf`` ops. Each function returns True when it rewrote the op; the op is
then replaced by a new one, so callers must not touch the old op afterwards.
"""

from __future__ import annotations

from kdsl.ir.catalog import PURE
from kdsl.ir.core import Operation, Value
from kdsl.ir.rewrite import rebuild_with_results


def drop_unused_if_results(op: Operation) -> bool:
    """Drop results of an ``scf.if`` that are unused, and their yield operands."""
    keep = [i for i, r in enumerate(op.results) if r.uses]
    if len(keep) == len(op.results):
        return False
    for region in op.regions:
        term = region.block.ops[-1]
        term.set_operands([term.operands[i] for i in keep])
    rebuild_with_results(op, keep, list(op.operands))
    return True


def _dead_cycle(arg: Value, yield_op: Operation, index: int) -> list[Operation] | None:
    """Pure ops fed by ``arg`` whose values reach only ``yield_op`` operand ``index``.

    Returns them (to be erased, users first) or None when the carried value matters
    elsewhere: a store, a nested region, a condition, another yielded value.
    """
    seen: list[Operation] = []
    work = [arg]
    visited: set[int] = set()
    while work:
        v = work.pop()
        for user, i in v.uses:
            if user is yield_op:
                if i != index:
                    return None
                continue
            if id(user) in visited:
                continue
            if PURE not in user.opdef.traits or user.regions or user.parent is not yield_op.parent:
                return None
            visited.add(id(user))
            seen.append(user)
            work.extend(user.results)
    return seen


def drop_dead_for_values(op: Operation) -> bool:
    """Remove carried values of an ``scf.for`` whose result is unused and whose value
    flows only back into its own yield (through pure ops of the body).

    A value that the body yields unchanged is replaced by its initial value first.
    """
    body = op.regions[0].block
    yield_op = body.ops[-1]
    changed = False
    n = len(op.results)
    for i in range(n):
        arg, init = body.args[i + 1], op.operands[3 + i]
        if yield_op.operands[i] is not arg:
            continue
        # Passed through unchanged: the value is ``init`` in every iteration and after.
        for user, j in [u for u in arg.uses if u[0] is not yield_op]:
            user.set_operand(j, init)
            changed = True
        if op.results[i].uses:
            op.results[i].replace_all_uses_with(init)
            changed = True
    dead: list[int] = []
    for i in range(n):
        if op.results[i].uses:
            continue
        ops = _dead_cycle(body.args[i + 1], yield_op, i)
        if ops is None:
            continue
        dead.append(i)
        yield_op.set_operand(i, body.args[i + 1])  # detach the chain from the yield
        _erase_dead(ops)
    if not dead:
        return changed
    keep = [i for i in range(n) if i not in dead]
    yield_op.set_operands([yield_op.operands[i] for i in keep])
    for i in reversed(dead):
        body.erase_arg(i + 1)
    operands = list(op.operands[:3]) + [op.operands[3 + i] for i in keep]
    rebuild_with_results(op, keep, operands)
    return True


def _erase_dead(ops: list[Operation]) -> None:
    """Erase pure ops that now feed nothing outside the set (users erased first)."""
    remaining = list(ops)
    while remaining:
        progressed = False
        for op in list(remaining):
            if not any(r.uses for r in op.results):
                op.erase()
                remaining.remove(op)
                progressed = True
        if not progressed:  # a cycle cannot exist in SSA; guard anyway
            raise AssertionError("dead loop-carried chain has a use cycle")


def _while_cycles(op: Operation) -> tuple[set[int], set[int]]:
    """Carried/passed index pairs (k, j) forming a cycle that nothing else reads.

    Before-argument ``k`` only goes to ``scf.condition`` as value ``j``, after-argument
    ``j`` only comes back as yielded value ``k``, and result ``j`` is unused.
    """
    before, after = op.regions[0].block, op.regions[1].block
    cond, yield_op = before.ops[-1], after.ops[-1]
    dead_in: set[int] = set()
    dead_out: set[int] = set()
    for k, arg in enumerate(before.args):
        if len(arg.uses) != 1 or arg.uses[0][0] is not cond:
            continue
        j = arg.uses[0][1] - 1
        if j < 0 or op.results[j].uses or after.args[j].uses != [(yield_op, k)]:
            continue
        dead_in.add(k)
        dead_out.add(j)
    return dead_in, dead_out


def drop_dead_while_values(op: Operation) -> bool:
    """Drop unused values of an ``scf.while``.

    A before-region argument without uses loses its initial value and the after
    region's matching yield operand; a value that ``scf.condition`` passes on but
    that neither the after region nor the op's users read is no longer passed; a
    value that only circulates (before argument -> condition -> after argument ->
    yield) with an unused result goes entirely.
    """
    before, after = op.regions[0].block, op.regions[1].block
    cond, yield_op = before.ops[-1], after.ops[-1]
    dead_in, dead_out = _while_cycles(op)
    keep_in = [i for i, a in enumerate(before.args) if a.uses and i not in dead_in]
    keep_out = [
        j for j, a in enumerate(after.args)
        if (a.uses or op.results[j].uses) and j not in dead_out
    ]  # fmt: skip
    if len(keep_in) == len(before.args) and len(keep_out) == len(after.args):
        return False
    yield_op.set_operands([yield_op.operands[i] for i in keep_in])
    cond.set_operands([cond.operands[0]] + [cond.operands[1 + j] for j in keep_out])
    for i in reversed(range(len(before.args))):
        if i not in keep_in:
            before.erase_arg(i)
    for j in reversed(range(len(after.args))):
        if j not in keep_out:
            after.erase_arg(j)
    rebuild_with_results(op, keep_out, [op.operands[i] for i in keep_in])
    return True
