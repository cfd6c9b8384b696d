"""The reverse of ``scf.for`` and ``scf.while``: a counted loop over the taped iterations.

The forward replay taped what the loop carried into each iteration and counted
its trips ``N``. The reverse is an ``scf.for`` over ``k = N-1 .. 0`` that carries
the adjoints of the differentiable carried values and of the outer values the body
reads: each reversed iteration reloads iteration ``k``'s carried values from the
tape, replays the body from them (re-taping any loop nested in it, so a nested
tape holds one instance at a time) and reverses it. A ``while`` loop first reverses
the last run of its ``before`` region (slot ``N``), which produced the results.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from kdsl.ir import Block, Operation, Region, Value
from kdsl.ir.types import I32
from kdsl.ir.vjp import is_differentiable
from kdsl.passes.adjoint.analysis import defined_in, outer_uses

if TYPE_CHECKING:
    from kdsl.passes.adjoint.reverse import Adjoints, ReverseSweep

#: One reversed iteration: ``(k, carried adjoints, outer adjoints)`` to the next ones.
IterationFn = Callable[[Value, list[Value], list[Value]], tuple[list[Value], list[Value]]]


def reverse_for(
    sweep: ReverseSweep, op: Operation, vmap: dict[Value, Value], adj: Adjoints
) -> None:
    """Emit the reverse of the ``scf.for`` ``op``; its operands' adjoints go into ``adj``."""
    b = sweep.b
    tape = sweep.tapes.table.of[op]
    body = op.regions[0].block
    carried = body.args[1:]
    nexts = body.terminator.operands
    diff = [j for j, a in enumerate(carried) if is_differentiable(a.type)]
    outer = outer_uses(op)
    seeds = [adj.get(op.results[j]) or sweep.zeros(carried[j].type) for j in diff]

    def one_iteration(k, carried_adj, outer_adj):
        xs = sweep.tapes.load(tape, k, [a.type for a in carried])
        lb, step = vmap[op.operands[0]], vmap[op.operands[2]]
        kk = k if lb.type == I32 else b.create("arith.cast", [k], [lb.type]).result
        iv = b.value("arith.add", lb, b.value("arith.mul", kk, step))
        inner = dict(vmap)
        inner[body.args[0]] = iv
        inner.update(zip(carried, xs))
        sweep.replay.replay(body, inner, record=True)
        a = dict(zip(outer, outer_adj))
        for j, g in zip(diff, carried_adj):
            sweep.accumulate(a, nexts[j], g)
        sweep.reverse_block(body, inner, a)
        return ([a.get(carried[j]) or sweep.zeros(carried[j].type) for j in diff],
                [a[o] for o in outer])  # fmt: skip

    final = _reverse_loop(sweep, op, adj, seeds, outer, one_iteration)
    for j, g in zip(diff, final):
        sweep.accumulate(adj, op.operands[3 + j], g)


def reverse_while(
    sweep: ReverseSweep, op: Operation, vmap: dict[Value, Value], adj: Adjoints
) -> None:
    """Emit the reverse of the ``scf.while`` ``op``; its operands' adjoints go into ``adj``."""
    tape = sweep.tapes.table.of[op]
    before, after = op.regions[0].block, op.regions[1].block
    passed = before.terminator.operands[1:]
    nexts = after.terminator.operands
    xtypes = [a.type for a in before.args]
    diff_x = [i for i, a in enumerate(before.args) if is_differentiable(a.type)]
    diff_v = [i for i, a in enumerate(after.args) if is_differentiable(a.type)]

    # The last run of the before region (slot N) produced the loop's results.
    n = sweep.replay.trips[op]
    inner = dict(vmap)
    inner.update(zip(before.args, sweep.tapes.load(tape, n, xtypes)))
    sweep.replay.replay(before, inner, record=True)
    last = dict(adj)
    for i in diff_v:
        sweep.accumulate(last, passed[i], adj.get(op.results[i]))
    sweep.reverse_block(before, inner, last)
    outside = defined_in(op)
    for k, v in last.items():
        if k not in outside:
            adj[k] = v
    seeds = [last.get(before.args[i]) or sweep.zeros(xtypes[i]) for i in diff_x]
    outer = outer_uses(op)

    def one_iteration(k, carried_adj, outer_adj):
        inner = dict(vmap)
        inner.update(zip(before.args, sweep.tapes.load(tape, k, xtypes)))
        outs = sweep.replay.replay(before, inner, record=True)
        inner.update(zip(after.args, outs[1:]))
        sweep.replay.replay(after, inner, record=True)
        a = dict(zip(outer, outer_adj))
        for i, g in zip(diff_x, carried_adj):
            sweep.accumulate(a, nexts[i], g)
        sweep.reverse_block(after, inner, a)
        for i in diff_v:
            sweep.accumulate(a, passed[i], a.get(after.args[i]))
        sweep.reverse_block(before, inner, a)
        return ([a.get(before.args[i]) or sweep.zeros(xtypes[i]) for i in diff_x],
                [a[o] for o in outer])  # fmt: skip

    final = _reverse_loop(sweep, op, adj, seeds, outer, one_iteration)
    for i, g in zip(diff_x, final):
        sweep.accumulate(adj, op.operands[i], g)


def _reverse_loop(
    sweep: ReverseSweep,
    op: Operation,
    adj: Adjoints,
    seeds: list[Value],
    outer: list[Value],
    body_fn: IterationFn,
) -> list[Value]:
    """A reversed counted loop over the taped iterations; gives the final adjoints.

    ``seeds`` are the adjoints carried in (one per differentiable carried value),
    ``outer`` the outer values whose adjoints the body may add to; ``body_fn(k,
    carried_adj, outer_adj)`` emits one reversed iteration and returns the next
    carried adjoints and the outer ones.
    """
    b = sweep.b
    n = sweep.replay.trips[op]
    zero, one = b.constant(0, I32), b.constant(1, I32)
    init = [*seeds, *[adj.get(o) or sweep.zeros(o.type) for o in outer]]
    blk = Block([I32] + [v.type for v in init])
    with b.at_end(blk):
        t = blk.args[0]
        k = b.value("arith.sub", b.value("arith.sub", n, one), t)
        carried = blk.args[1 : 1 + len(seeds)]
        outer_adj = blk.args[1 + len(seeds) :]
        nxt, nxt_outer = body_fn(k, list(carried), list(outer_adj))
        b.create("scf.yield", [*nxt, *nxt_outer])
    new = b.create("scf.for", [zero, n, one, *init], [v.type for v in init],
                   regions=[Region(blk)])  # fmt: skip
    res = list(new.results)
    for o, r in zip(outer, res[len(seeds) :]):
        adj[o] = r
    return res[: len(seeds)]
