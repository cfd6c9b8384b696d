"""Lane blocks: a thread loop around a uniform loop, turned inside out so threads vectorize.

A kernel such as the ocean scene's ``gerstner`` reads its point, loops over the waves
(a trip count every thread shares, read from a parameter array's shape) and stores the
sum. Its thread loop holds that wave loop, so LLVM's loop vectorizer (innermost loops
only) never sees the threads side by side, and each thread's ``sin``/``cos`` runs
alone. The sum over waves is a float reduction, which it may not reorder either.

So such a kernel's thread loop runs ``LANES`` threads at a time, as three loops over
the lanes: the code before the uniform loop (the prologue) for each lane, then the
uniform loop with, inside it, one lane loop running its body for every lane, then the
code after it (the epilogue) for each lane. The values that cross from one lane loop
to the next (the prologue's values the rest uses, the loop's carried values) wait in
small per-lane arrays (``alloca [LANES x T]``: lane ``l`` touches element ``l`` only),
so each lane loop is innermost, its iterations independent (``loop_md``'s access group
and parallel loop id), and LLVM vectorizes it across lanes. Each thread still does its
own operations in its own order: the results are the same bits. The threads left
over after the last whole block run in the ordinary thread loop.

A kernel qualifies (``lane_plan``) when its thread loop may be marked parallel
(``loop_md.thread_parallel``), its index is 1-d, and its body is a prologue without
loops, one ``scf.for`` whose bounds and step come from parameters and constants only
and which holds no loop itself, and an epilogue without loops.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from llvmlite import ir

from kdsl.backends.base import split_block
from kdsl.backends.cpu import loop_md
from kdsl.backends.cpu import types as LT
from kdsl.backends.cpu.composite import leaf_types, leaves, rebuild_all
from kdsl.backends.cpu.control import loop_test
from kdsl.backends.cpu.emitter import Emitter
from kdsl.ir.catalog import PURE
from kdsl.ir.core import Operation, Value

#: Threads per block: a lane loop's trip count (LLVM picks the vector width within it).
LANES = 16
_LOOPS = ("scf.for", "scf.while")


@dataclass
class LanePlan:
    """How a kernel's body splits around its uniform loop (see the module docstring)."""

    #: Ops before the loop computed from parameters and constants alone: emitted once.
    uniform: list[Operation]
    #: The other ops before the loop: emitted per lane.
    prologue: list[Operation]
    loop: Operation
    #: Ops after the loop (its terminator excluded): emitted per lane.
    epilogue: list[Operation]
    #: Prologue values the loop or the epilogue reads: kept per lane between lane loops.
    crossing: list[Value]


def _has_loop(op: Operation) -> bool:
    return any(o.name in _LOOPS for o in op.walk())


def lane_plan(kernel: Operation) -> LanePlan | None:
    """The lane-block plan of ``kernel``, or None when it does not qualify."""
    if not loop_md.thread_parallel(kernel):
        return None
    ops, _ = split_block(kernel.regions[0].block)
    if any(o.name == "kd.tid" and o.attrs["ndim"] != 1 for top in ops for o in top.walk()):
        return None
    loops = [k for k, op in enumerate(ops) if _has_loop(op)]
    if len(loops) != 1 or ops[loops[0]].name != "scf.for":
        return None
    at = loops[0]
    loop = ops[at]
    if any(o.name in _LOOPS for o in list(loop.walk())[1:]):
        return None
    uniform_values: set[Value] = set(kernel.regions[0].block.args)
    uniform, prologue = [], []
    for op in ops[:at]:
        if (PURE in op.opdef.traits and not op.regions and op.name != "kd.tid"
                and all(v in uniform_values for v in op.operands)):  # fmt: skip
            uniform.append(op)
            uniform_values.update(op.results)
        else:
            prologue.append(op)
    if not all(v in uniform_values for v in loop.operands[:3]):
        return None
    made = {r for op in prologue for r in op.results}
    epilogue = ops[at + 1 :]
    crossing: list[Value] = []
    for op in (loop, *epilogue):
        for inner in op.walk():
            for v in inner.operands:
                if v in made and v not in crossing:
                    crossing.append(v)
    return LanePlan(uniform, prologue, loop, epilogue, crossing)


class _Slots:
    """Per-lane arrays (``alloca [LANES x T]`` in the entry block) for a list of values."""

    def __init__(self, em: Emitter, types: list[Any]) -> None:
        self.em, self.types = em, types
        B = em.b
        here = B.block
        B.position_at_start(em.fn.entry_basic_block)
        self.arrays = [[B.alloca(ir.ArrayType(lt, LANES)) for lt in leaf_types(t)] for t in types]
        B.position_at_end(here)

    def _at(self, array: ir.Value, lane: ir.Value) -> ir.Value:
        return self.em.b.gep(array, [ir.Constant(LT.I32, 0), lane], inbounds=True)

    def store(self, values: list[Any], lane: ir.Value) -> None:
        """Keep ``values`` (one per type) for ``lane``."""
        em = self.em
        for v, arrays in zip(values, self.arrays):
            for leaf, array in zip(leaves(v), arrays):
                ins = em.b.store(leaf, self._at(array, lane))
                loop_md.mark_access([ins], em.access_group)

    def load(self, lane: ir.Value) -> list[Any]:
        """The values kept for ``lane``."""
        em = self.em
        flat = []
        for arrays in self.arrays:
            for array in arrays:
                ins = em.b.load(self._at(array, lane), typ=array.allocated_type.element)
                loop_md.mark_access([ins], em.access_group)
                flat.append(ins)
        return rebuild_all(self.types, flat)


def _loop(
    em: Emitter,
    name: str,
    start: ir.Value,
    test: Callable[[ir.Value], ir.Value],
    step: Callable[[ir.Value], ir.Value],
    run: Callable[[ir.Value], None],
    parallel: bool = False,
) -> ir.Value:
    """A loop on one counter from ``start``: while ``test(i)``, ``run(i)`` then ``i =
    step(i)``; marked parallel (``loop_md``) when asked. Gives the counter (its value
    in the exit block, where the builder ends, is the first that failed the test)."""
    B, fn = em.b, em.fn
    entry = B.block
    head, body, done = (fn.append_basic_block(f"{name}.{n}") for n in ("head", "body", "exit"))
    B.branch(head)
    B.position_at_end(head)
    i = B.phi(start.type, name=name)
    i.add_incoming(start, entry)
    B.cbranch(test(i), body, done)
    B.position_at_end(body)
    run(i)
    i.add_incoming(step(i), B.block)
    latch = B.branch(head)
    if parallel:
        latch.set_metadata("llvm.loop", loop_md.parallel_loop(em.state.llmod, em.access_group))
    B.position_at_end(done)
    return i


def _lane_loop(em: Emitter, name: str, run: Callable[[ir.Value], None]) -> None:
    """``run(lane)`` for lanes 0 to ``LANES - 1`` in a loop marked parallel."""
    B = em.b
    _loop(em, name, ir.Constant(LT.I32, 0),
          lambda lane: B.icmp_signed("<", lane, ir.Constant(LT.I32, LANES)),
          lambda lane: B.add(lane, ir.Constant(LT.I32, 1), flags=["nsw", "nuw"]),
          run, parallel=True)  # fmt: skip


def emit(
    em: Emitter,
    plan: LanePlan,
    lo: ir.Value,
    hi: ir.Value,
    rest: Callable[[ir.Value, ir.Value], None],
) -> None:
    """Threads ``[lo, hi)`` (i32) in whole blocks of ``LANES``, then ``rest(first, hi)``
    runs the ones left in the ordinary thread loop. The builder ends in its exit block."""
    B = em.b
    for op in plan.uniform:
        em.lower_op(op)
    keep = _Slots(em, [v.type for v in plan.crossing])
    loop = plan.loop
    carried_types = [r.type for r in loop.results]
    carry = _Slots(em, carried_types)
    lb, ub, step = (em.get(v) for v in loop.operands[:3])
    last = B.sub(hi, ir.Constant(LT.I32, LANES))  # a block starting at or before it is whole
    first: ir.Value = lo  # the block's first thread (the loop's counter, in ``block``)

    def at(lane: ir.Value) -> None:
        em.linear = B.add(first, lane, flags=["nsw"])
        em.index = []

    def prologue(lane: ir.Value) -> None:
        at(lane)
        for op in plan.prologue:
            em.lower_op(op)
        keep.store([em.get(v) for v in plan.crossing], lane)
        carry.store([em.get(v) for v in loop.operands[3:]], lane)

    def step_lane(iv: ir.Value) -> Callable[[ir.Value], None]:
        def run(lane: ir.Value) -> None:
            at(lane)
            em.bind(plan.crossing, keep.load(lane))
            carry.store(em.lower_block(loop.regions[0].block, [iv, *carry.load(lane)]), lane)

        return run

    def epilogue(lane: ir.Value) -> None:
        at(lane)
        em.bind(plan.crossing, keep.load(lane))
        em.bind(loop.results, carry.load(lane))
        for op in plan.epilogue:
            em.lower_op(op)

    def block(start: ir.Value) -> None:
        nonlocal first
        first = start
        _lane_loop(em, "lane.pro", prologue)
        signed = loop.operands[0].type.is_signed
        _uniform_loop(em, lb, ub, step, signed,
                      lambda iv: _lane_loop(em, "lane.step", step_lane(iv)))  # fmt: skip
        _lane_loop(em, "lane.epi", epilogue)

    def whole(start: ir.Value) -> ir.Value:
        return B.and_(B.icmp_signed("<=", start, last), B.icmp_signed("<", start, hi))

    after = _loop(em, "lanes", lo, whole,
                  lambda start: B.add(start, ir.Constant(LT.I32, LANES), flags=["nsw"]),
                  block)  # fmt: skip
    rest(after, hi)


def _uniform_loop(
    em: Emitter,
    lb: ir.Value,
    ub: ir.Value,
    step: ir.Value,
    signed: bool,
    run: Callable[[ir.Value], None],
) -> None:
    """``run(iv)`` for ``iv`` from ``lb`` by ``step`` while ``control.loop_test`` holds."""
    _loop(em, "uniform", lb, lambda iv: loop_test(em, iv, ub, step, signed),
          lambda iv: em.b.add(iv, step), run)  # fmt: skip
