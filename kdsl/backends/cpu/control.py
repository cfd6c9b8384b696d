"""Lowerings of structured control flow to basic blocks with phis, and of calls.

``scf.if`` becomes a diamond, ``scf.for`` and ``scf.while`` a header block whose
phis carry the loop values. Callees of ``func.call`` become internal LLVM
functions of the same module (after inlining there usually are none).
"""

from __future__ import annotations

from llvmlite import ir

from kdsl.backends.cpu import checks
from kdsl.backends.cpu import types as LT
from kdsl.backends.cpu.emitter import Emitter, Lowering
from kdsl.ir import types as T
from kdsl.ir.core import Operation


def _phis(em: Emitter, values: list[ir.Value], pred: ir.Block, name: str) -> list[ir.Instruction]:
    phis = []
    for v in values:
        phi = em.b.phi(v.type, name=name)
        phi.add_incoming(v, pred)
        phis.append(phi)
    return phis


def _if(em: Emitter, op: Operation) -> list[ir.Value]:
    B = em.b
    then_bb, else_bb, merge_bb = (
        em.new_block("if.then"),
        em.new_block("if.else"),
        em.new_block("if.end"),
    )
    B.cbranch(em.get(op.operands[0]), then_bb, else_bb)
    incoming = []
    for bb, region in ((then_bb, op.regions[0]), (else_bb, op.regions[1])):
        B.position_at_end(bb)
        vals = em.lower_block(region.block)
        incoming.append((vals, B.block))
        B.branch(merge_bb)
    B.position_at_end(merge_bb)
    results = []
    for i, r in enumerate(op.results):
        phi = B.phi(LT.llvm_type(r.type), name="if.val")
        for vals, bb in incoming:
            phi.add_incoming(vals[i], bb)
        results.append(phi)
    return results


def _for(em: Emitter, op: Operation) -> list[ir.Value]:
    B = em.b
    lb, ub, step, *init = em.args(op)
    it: T.ScalarType = op.operands[0].type
    entry = B.block
    head, body, done = em.new_block("for.head"), em.new_block("for.body"), em.new_block("for.end")
    B.branch(head)
    B.position_at_end(head)
    iv, *carried = _phis(em, [lb, *init], entry, "for.iv")
    zero = em.const(step.type, 0)
    lt = B.icmp_signed("<", iv, ub) if it.is_signed else B.icmp_unsigned("<", iv, ub)
    if it.is_signed:  # a negative step counts down, a zero step runs nothing
        gt = B.icmp_signed(">", iv, ub)
        up = B.icmp_signed(">", step, zero)
        down = B.icmp_signed("<", step, zero)
        go = B.or_(B.and_(up, lt), B.and_(down, gt))
    else:
        go = B.and_(B.icmp_unsigned("!=", step, zero), lt)
    B.cbranch(go, body, done)
    B.position_at_end(body)
    nxt = em.lower_block(op.regions[0].block, [iv, *carried])
    latch = B.block
    iv.add_incoming(B.add(iv, step), latch)
    for phi, v in zip(carried, nxt):
        phi.add_incoming(v, latch)
    B.branch(head)
    B.position_at_end(done)
    return carried


def _while(em: Emitter, op: Operation) -> list[ir.Value]:
    B = em.b
    entry = B.block
    head, after, done = (
        em.new_block("while.head"),
        em.new_block("while.body"),
        em.new_block("while.end"),
    )
    B.branch(head)
    B.position_at_end(head)
    carried = _phis(em, em.args(op), entry, "while.val")
    cond, *passed = em.lower_block(op.regions[0].block, carried)
    B.cbranch(cond, after, done)
    B.position_at_end(after)
    nxt = em.lower_block(op.regions[1].block, passed)
    for phi, v in zip(carried, nxt):
        phi.add_incoming(v, B.block)
    B.branch(head)
    B.position_at_end(done)
    return passed


def _call(em: Emitter, op: Operation) -> list[ir.Value]:
    from kdsl.backends.cpu.lower import declare_func  # lower imports the table

    fn = declare_func(em.state, op.attrs["callee"])
    args = em.args(op)
    if em.error_record is not None:  # debug build: pass the record on, stop if it failed
        args.append(em.error_record)
    out = em.b.call(fn, args)
    checks.stop_if_failed(em)
    if not op.results:
        return []
    if len(op.results) == 1:
        return [out]
    return [em.b.extract_value(out, i) for i in range(len(op.results))]


TABLE: dict[str, Lowering] = {
    "scf.if": _if,
    "scf.for": _for,
    "scf.while": _while,
    "func.call": _call,
}
