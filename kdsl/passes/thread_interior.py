"""Thread-index bounds tests and the interior of a kernel's launch (boundary peeling).

A stencil written naturally tests its thread index against the edges of the grid
(``if i == 0 or j == n - 1: ...``). Every such test, ``t + c PRED K`` with ``t`` a
component of ``kd.tid``, ``c`` an integer constant and ``K`` a launch-invariant
integer (a constant, a scalar parameter, an array extent, pure arithmetic on
those), has one answer on a whole half-line of ``t``. ``interior_plan`` finds them
and gives:

- per thread dimension, the cuts: run-time values ``p`` with a side. A cut on the
  low side says "for ``t >= p`` the test has answer A", on the high side "for
  ``t < p``". The box where every cut holds is the interior of the launch;
- a copy of the kernel in which each test is replaced by its interior answer and
  which is then folded (``fold``, ``canonicalize``, ``dce``): the body without the
  edge branches.

Which side a test gets is a heuristic (a constant ``K`` marks a low edge, any other
``K`` a high edge), but the answers are right by construction on whichever box the
cuts describe: the transform is exact whatever the data. The cpu backend runs the
copy on the interior columns and the kernel itself on the edges
(``kdsl.backends.cpu.lower``); the interior copy only needs the cuts' values, which
are computed once per launch from the kernel's parameters.

``thread-interior`` as a pass is an inspection aid for ``kdsl opt`` and tests: it
adds the interior copy of each kernel that has one as the function
``@<kernel>__interior`` and records each kernel's cuts in its ``interior_cuts``
attribute (``"d<dim>:<lo|hi>"`` per test, in the order of the plan).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

from kdsl.ir import Module, Operation, Value
from kdsl.ir.catalog import CONSTANT_LIKE
from kdsl.ir.core import BlockArgument, OpResult
from kdsl.ir.rewrite import clone_op, constant_of, is_speculatable, make_constant, replace_op
from kdsl.ir.types import BOOL, ScalarType
from kdsl.passes.manager import ModulePass, run_fixpoint

#: A test ``t PRED m`` with ``K`` on the other side: (the cut's offset from m, answer on
#: the low side t >= cut, answer on the high side t < cut).
_CUTS = {
    "lt": (0, False, True),
    "le": (1, False, True),
    "gt": (1, True, False),
    "ge": (0, True, False),
    "eq": (None, False, False),  # one point: low cut m + 1, high cut m
    "ne": (None, True, True),
}
_SWAP = {"lt": "gt", "le": "ge", "gt": "lt", "ge": "le", "eq": "eq", "ne": "ne"}
_INT32_MAX = 2**31 - 1


@dataclass(frozen=True)
class Cut:
    """One bounds test: ``t_dim + offset PRED bound``, exact on one side of ``at``.

    The cut's position is ``bound - offset + shift`` (``bound`` None: 0).
    ``low``: the test has its interior answer for ``t >= position``; else for
    ``t < position``.
    """

    dim: int
    bound: Value | None
    const: int  # bound's value when it is a constant (bound None)
    offset: int
    shift: int
    low: bool


@dataclass
class InteriorPlan:
    """The cuts of a kernel's bounds tests and its body with their interior answers."""

    ndim: int
    cuts: list[Cut]
    #: A ``func.func`` copy of the kernel whose bounds tests are folded away.
    interior: Operation
    #: The ops (in order) that compute the cuts' bounds from the parameters.
    invariant_ops: list[Operation] = field(default_factory=list)

    def dims(self) -> set[int]:
        """The thread dimensions with at least one cut."""
        return {c.dim for c in self.cuts}


def interior_plan(module: Module, kernel: Operation) -> InteriorPlan | None:
    """The plan of ``kernel`` (a ``func.func`` of kind kernel), or None without tests."""
    body = kernel.regions[0].block
    tids = [op for op in kernel.walk() if op.name == "kd.tid"]
    ndims = {op.attrs["ndim"] for op in tids}
    if len(ndims) != 1:
        return None
    ndim = ndims.pop()
    params = set(body.args)
    invariant: dict[Value, bool] = {}
    found: list[tuple[Operation, Cut, bool]] = []
    for op in kernel.walk():
        if op.name != "arith.cmp":
            continue
        hit = _match(op, params, invariant)
        if hit is not None:
            found.append((op, *hit))
    if not found:
        return None
    order: list[Operation] = []
    seen: set[Operation] = set()
    for _, cut, _ in found:
        if cut.bound is not None:
            _collect(cut.bound, order, seen)
    interior = _interior_copy(module, kernel, {op: answer for op, _, answer in found})
    return InteriorPlan(ndim, [c for _, c, _ in found], interior, order)


def _int_type(v: Value) -> bool:
    t = v.type
    return isinstance(t, ScalarType) and t.is_int and t.is_signed and t.bits == 32


def _tid_offset(v: Value) -> tuple[int, int] | None:
    """``(dim, c)`` if ``v`` is ``tid_dim + c`` (c an integer constant, maybe 0)."""
    if not isinstance(v, OpResult):
        return None
    op = v.op
    if op.name == "kd.tid":
        return op.attrs["dim"], 0
    if op.name in ("arith.add", "arith.sub") and _int_type(v):
        a, b = op.operands
        okb, cb = constant_of(b)
        if okb and isinstance(a, OpResult) and a.op.name == "kd.tid":
            c = int(cb) if op.name == "arith.add" else -int(cb)
            if abs(c) < 2**20:
                return a.op.attrs["dim"], c
        oka, ca = constant_of(a)
        tid_b = isinstance(b, OpResult) and b.op.name == "kd.tid"
        if oka and op.name == "arith.add" and tid_b and abs(int(ca)) < 2**20:
            return b.op.attrs["dim"], int(ca)
    return None


def _is_invariant(v: Value, params: set[Value], memo: dict[Value, bool]) -> bool:
    """True if ``v`` is the same in every thread and computable before the thread loop."""
    known = memo.get(v)
    if known is not None:
        return known
    memo[v] = False  # cycles (loop-carried values) are not invariant
    if isinstance(v, BlockArgument):
        ok = v in params
    else:
        op = v.op
        if CONSTANT_LIKE in op.opdef.traits:
            ok = True
        else:
            ok = (
                op.name != "kd.tid"
                and bool(op.operands)
                and len(op.results) == 1
                and is_speculatable(op)
                and all(_is_invariant(o, params, memo) for o in op.operands)
            )
    memo[v] = ok
    return ok


def _match(op: Operation, params: set[Value], memo: dict[Value, bool]) -> tuple[Cut, bool] | None:
    """The cut of the comparison ``op`` and its interior answer, if it is a bounds test."""
    a, b = op.operands
    if not (_int_type(a) and _int_type(b)):
        return None
    pred = op.attrs["pred"]
    lhs = _tid_offset(a)
    if lhs is not None and _is_invariant(b, params, memo) and _tid_offset(b) is None:
        other = b
    else:
        lhs = _tid_offset(b)
        if lhs is None or not _is_invariant(a, params, memo) or _tid_offset(a) is not None:
            return None
        other, pred = a, _SWAP[pred]
    dim, offset = lhs
    ok, value = constant_of(other)
    low = ok  # a constant marks a low edge, anything else a high edge
    shift, low_answer, high_answer = _CUTS[pred]
    if shift is None:
        shift = 1 if low else 0
    cut = Cut(dim, None if ok else other, int(value) if ok else 0, offset, shift, low)
    return cut, low_answer if low else high_answer


def _collect(v: Value, order: list[Operation], seen: set[Operation]) -> None:
    """Append the ops computing ``v`` (operands first) to ``order``."""
    if not isinstance(v, OpResult) or v.op in seen:
        return
    for o in v.op.operands:
        _collect(o, order, seen)
    if v.op not in seen:
        seen.add(v.op)
        order.append(v.op)


def _interior_copy(module: Module, kernel: Operation, answers: dict[Operation, bool]) -> Operation:
    """A folded copy of ``kernel`` with each op of ``answers`` replaced by its answer."""
    mapping: dict[Value, Value] = {}
    copy = clone_op(kernel, mapping)
    copy.attrs["sym_name"] = kernel.attrs["sym_name"] + "__interior"
    copy.attrs["kind"] = "func"
    old_of = {mapping[op.result]: op for op in answers}
    for op in list(copy.walk()):
        if op.name == "arith.cmp" and op.result in old_of:
            answer = answers[old_of[op.result]]
            replace_op(op, [make_constant(answer, BOOL, op)])
    scratch = Module(module.name)
    scratch.structs = dict(module.structs)
    scratch.add_func(copy)
    run_fixpoint(scratch, "fold,canonicalize,dce")
    scratch.body.detach(copy)
    return copy


def cut_position(cut: Cut) -> tuple[Value | None, int]:
    """``(value, k)``: the cut sits at ``value + k`` (``value`` None: at ``k``).

    Also bounds the interior so ``t + offset`` cannot wrap in 32 bits.
    """
    if cut.bound is None:
        return None, cut.const - cut.offset + cut.shift
    return cut.bound, cut.shift - cut.offset


def wrap_limit(cut: Cut) -> int | None:
    """The high cut that keeps ``t + offset`` in int32 (None when no wrap is possible)."""
    return _INT32_MAX - cut.offset + 1 if cut.offset > 0 else None


@dataclass(frozen=True)
class ThreadInteriorPass(ModulePass):
    """Inspection: adds each kernel's interior copy as ``@<kernel>__interior``."""

    name: ClassVar[str] = "thread-interior"

    def apply(self, module: Module) -> bool:
        changed = False
        funcs = module.funcs
        for k, func in enumerate(funcs):
            if func.attrs.get("kind") != "kernel":
                continue
            plan = interior_plan(module, func)
            if plan is None:
                continue
            func.attrs["interior_cuts"] = [f"d{c.dim}:{'lo' if c.low else 'hi'}" for c in plan.cuts]
            if k + 1 < len(funcs):  # right after its kernel
                module.body.insert_before(funcs[k + 1], plan.interior)
            else:
                module.add_func(plan.interior)
            changed = True
        return changed
