"""Lowerings of structured control flow to basic blocks with phis, and of calls.

``scf.if`` becomes a diamond, ``scf.for`` and ``scf.while`` a header block whose
phis carry the loop values. Callees of ``func.call`` become internal LLVM
functions of the same module (after inlining there usually are none). Vector,
matrix and struct values cross phis and calls as their leaves (``composite``):
one phi per scalar component, one parameter per component.
"""

from __future__ import annotations

from typing import Any

from llvmlite import ir

from kdsl.backends.cpu import checks, loop_md, versioning
from kdsl.backends.cpu.composite import leaf_types, leaves, rebuild_all
from kdsl.backends.cpu.emitter import Emitter
from kdsl.ir import types as T
from kdsl.ir.core import Operation
from kdsl.ir.lowering import LOWERINGS
from kdsl.ir.rewrite import constant_of

CPU = LOWERINGS.for_backend("cpu")


def _phis(em: Emitter, values: list[Any], pred: ir.Block, name: str) -> list[ir.Instruction]:
    """One phi per leaf of ``values`` (see ``composite``), entered from ``pred``."""
    phis = []
    for v in values:
        phi = em.b.phi(v.type, name=name)
        phi.add_incoming(v, pred)
        phis.append(phi)
    return phis


def _add_incoming(phis: list[ir.Instruction], values: list[Any], pred: ir.Block) -> None:
    for phi, v in zip(phis, _flat(values)):
        phi.add_incoming(v, pred)


def _flat(values: list[Any]) -> list[ir.Value]:
    return [leaf for v in values for leaf in leaves(v)]


def _if(em: Emitter, op: Operation) -> list[Any]:
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
        vals = _flat(em.lower_block(region.block))
        incoming.append((vals, B.block))
        B.branch(merge_bb)
    B.position_at_end(merge_bb)
    types = [lt for r in op.results for lt in leaf_types(r.type)]
    phis = [B.phi(lt, name="if.val") for lt in types]
    for vals, bb in incoming:
        _add_incoming(phis, vals, bb)
    return rebuild_all([r.type for r in op.results], phis)


def _for(em: Emitter, op: Operation) -> list[Any]:
    trips = loop_md.short_trips(op) if em.unroll_inside else None
    if trips is not None:
        return _unrolled_for(em, op, trips)
    arrays = versioning.arrays_to_version(op)
    if not arrays:
        return _emit_for(em, op)
    types = [r.type for r in op.results]
    return versioning.versioned(em, arrays, lambda: _emit_for(em, op), types)


def _emit_for(em: Emitter, op: Operation) -> list[Any]:
    B = em.b
    lb, ub, step, *init = em.args(op)
    it: T.ScalarType = op.operands[0].type
    types = [r.type for r in op.results]
    entry = B.block
    head, body, done = em.new_block("for.head"), em.new_block("for.body"), em.new_block("for.end")
    B.branch(head)
    B.position_at_end(head)
    (iv,) = _phis(em, [lb], entry, "for.iv")
    phis = _phis(em, _flat(init), entry, "for.val")
    carried = rebuild_all(types, phis)
    B.cbranch(loop_test(em, iv, ub, step, it.is_signed), body, done)
    B.position_at_end(body)
    nxt = em.lower_block(op.regions[0].block, [iv, *carried])
    latch = B.block
    iv.add_incoming(B.add(iv, step), latch)
    _add_incoming(phis, nxt, latch)
    B.branch(head)
    B.position_at_end(done)
    return carried


def loop_test(em: Emitter, iv: ir.Value, ub: ir.Value, step: ir.Value, signed: bool) -> ir.Value:
    """Whether ``scf.for`` runs its body at ``iv``: before ``ub`` in ``step``'s direction
    (a negative step counts down when signed; a zero step runs nothing)."""
    B = em.b
    zero = em.const(step.type, 0)
    lt = B.icmp_signed("<", iv, ub) if signed else B.icmp_unsigned("<", iv, ub)
    if not signed:
        return B.and_(B.icmp_unsigned("!=", step, zero), lt)
    up = B.and_(B.icmp_signed(">", step, zero), lt)
    down = B.and_(B.icmp_signed("<", step, zero), B.icmp_signed(">", iv, ub))
    return B.or_(up, down)


def _unrolled_for(em: Emitter, op: Operation, trips: int) -> list[Any]:
    """``scf.for`` with constant bounds, its body emitted once per trip (``loop_md``)."""
    lb, _, _, *carried = em.args(op)
    lo, step = constant_of(op.operands[0])[1], constant_of(op.operands[2])[1]
    for k in range(trips):
        iv = ir.Constant(lb.type, lo + k * step)
        carried = em.lower_block(op.regions[0].block, [iv, *carried])
    return carried


def _while(em: Emitter, op: Operation) -> list[Any]:
    B = em.b
    entry = B.block
    head, after, done = (
        em.new_block("while.head"),
        em.new_block("while.body"),
        em.new_block("while.end"),
    )
    B.branch(head)
    B.position_at_end(head)
    phis = _phis(em, _flat(em.args(op)), entry, "while.val")
    carried = rebuild_all([v.type for v in op.operands], phis)
    cond, *passed = em.lower_block(op.regions[0].block, carried)
    B.cbranch(cond, after, done)
    B.position_at_end(after)
    nxt = em.lower_block(op.regions[1].block, passed)
    _add_incoming(phis, nxt, B.block)
    B.branch(head)
    B.position_at_end(done)
    return passed


def _call(em: Emitter, op: Operation) -> list[Any]:
    from kdsl.backends.cpu.lower import declare_func  # lower imports the table

    fn = declare_func(em.state, op.attrs["callee"])
    args = _flat(em.args(op))
    if em.error_record is not None:  # debug build: pass the record on, stop if it failed
        args.append(em.error_record)
    out = em.b.call(fn, args)
    checks.stop_if_failed(em)
    types = [r.type for r in op.results]
    n = sum(len(leaf_types(t)) for t in types)
    if n == 0:
        return rebuild_all(types, [])
    if n == 1:
        return rebuild_all(types, [out])
    return rebuild_all(types, [em.b.extract_value(out, i) for i in range(n)])


CPU.register("scf.if", _if)
CPU.register("scf.for", _for)
CPU.register("scf.while", _while)
CPU.register("func.call", _call)

# Ops lowered as part of another lowering, never on their own.
CPU.structural("func.func", "`lower.emit_kernel` (kernels), `lower.declare_func` (functions)")
