"""Loop tapes: the values each loop carries into each iteration, stored per thread.

Replaying a loop in the adjoint stores what it carries into iteration ``k`` (all of
it, ints and flags included) so that the reverse sweep can reload iteration ``k``
and replay its body from there. A tape is a set of hidden 2-d array parameters of
the adjoint function, ``tape<L>_<j>`` indexed ``[thread, iteration]``, one per leaf
of the carried values: structs flatten into their fields and bools store as
``i8``. A store past a tape's end (a trip count the counting function did not
foresee) is skipped and sets ``tape_status[0]``, which the runtime turns into an
error. The adjoint function records the layout in its ``tape_leaves``,
``tape_slots`` (-1: sized at run time) and ``tape_sites`` attributes.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Protocol

from kdsl.errors import KdslError
from kdsl.ir import Block, Builder, Operation, Region, Value
from kdsl.ir.types import BOOL, I8, I32, ArrayType, StructType, Type

#: Attribute of the ``scf.if`` that guards a tape store (its value: the tape's index).
TAPE_GUARD = "tape_guard"
#: Name of the hidden status array a tape overflow writes to.
STATUS_PARAM = "tape_status"
_TAPE_PARAM = re.compile(r"tape\d+_\d+")


def tape_param_name(index: int, leaf: int) -> str:
    """The name of the hidden parameter holding leaf ``leaf`` of tape ``index``."""
    return f"tape{index}_{leaf}"


def is_tape_param(name: str | None) -> bool:
    """Whether a hidden parameter called ``name`` is a tape (not a flag or mask)."""
    return _TAPE_PARAM.fullmatch(name or "") is not None


@dataclass
class LoopTape:
    """The tape of one loop: hidden array parameters holding its carried values."""

    index: int
    op: Operation
    leaves: list[Type]
    static_slots: int | None
    params: list[Value] = field(default_factory=list)

    @property
    def site(self) -> str:
        """The loop's source location, for the runtime's messages."""
        return str(self.op.loc)


def leaf_types(t: Type) -> list[Type]:
    """Storage types of one carried value: structs flatten, bools store as i8."""
    if isinstance(t, StructType):
        return [leaf for _, ft in t.fields for leaf in leaf_types(ft)]
    if isinstance(t, ArrayType) or not t.is_value:
        raise TypeError(t)
    return [I8 if t == BOOL else t]


def carried_values(op: Operation) -> list[Value]:
    """The values an ``scf.for`` or ``scf.while`` carries into each iteration."""
    block = op.regions[0].block
    return list(block.args[1:] if op.name == "scf.for" else block.args)


def static_trips(op: Operation) -> int | None:
    """The trip count of an ``scf.for`` with constant bounds, else None."""
    if op.name != "scf.for":
        return None
    lb, ub, st = (_constant(v) for v in op.operands[:3])
    if lb is None or ub is None or st is None:
        return None
    return len(range(lb, ub, st)) if st != 0 else 0


def _constant(v: Value) -> int | None:
    op = getattr(v, "op", None)
    if op is not None and op.name == "arith.constant":
        return int(op.attrs["value"])
    return None


class TapeTable:
    """The tapes of one kernel's loops, numbered in the order the adjoint meets them.

    Shared by the adjoint function and the counting function, so that both number a
    loop's tape the same way.
    """

    def __init__(self, sym: str) -> None:
        self.sym = sym
        self.tapes: list[LoopTape] = []
        self.of: dict[Operation, LoopTape] = {}

    def lookup(self, op: Operation) -> tuple[LoopTape, bool]:
        """The tape of loop ``op`` and whether it was just made (it then has no params)."""
        tape = self.of.get(op)
        if tape is not None:
            return tape, False
        leaves: list[Type] = []
        for v in carried_values(op):
            try:
                leaves += leaf_types(v.type)
            except TypeError:
                raise KdslError(
                    f"kdsl cannot differentiate a loop that carries a {v.type} value "
                    f"('{v.name_hint or '?'}') from one iteration to the next",
                    op.loc, self.sym) from None  # fmt: skip
        tape = LoopTape(len(self.tapes), op, leaves, static_trips(op))
        self.tapes.append(tape)
        self.of[op] = tape
        return tape, True

    def all_static(self) -> bool:
        """Whether every tape's size is known without running the kernel."""
        return all(t.static_slots is not None for t in self.tapes)


class TapeSink(Protocol):
    """What the forward replay does with a loop it tapes (``TapeWriter``, ``TripCounter``)."""

    #: Tape loops at any depth, not only those the replay records.
    every_loop: bool

    def tape(self, op: Operation) -> LoopTape:
        """The tape of loop ``op``."""
        ...

    def store(self, tape: LoopTape, k: Value, values: Iterable[Value]) -> None:
        """Save ``values``, carried into iteration ``k``."""
        ...

    def record_trips(self, tape: LoopTape, slots: Value) -> None:
        """Note that the loop used ``slots`` tape slots."""
        ...


class TapeWriter:
    """The tape traffic of the adjoint function: parameters, stores, reloads, status.

    ``b`` is the builder the sweeps emit with, ``body`` the adjoint function's block
    (hidden parameters are added to it as they are needed) and ``ltid`` the linear
    thread index, the tapes' first index.
    """

    #: The reverse sweep re-tapes a nested loop inside each reversed outer iteration.
    every_loop = False

    def __init__(self, table: TapeTable, b: Builder, body: Block, ltid: Value) -> None:
        self.table = table
        self.b = b
        self.body = body
        self.ltid = ltid
        self._status: Value | None = None

    def tape(self, op: Operation) -> LoopTape:
        """The tape of loop ``op``, with its hidden parameters."""
        tape, new = self.table.lookup(op)
        if new:
            for j, t in enumerate(tape.leaves):
                tape.params.append(
                    self.body.add_arg(ArrayType(t, 2), tape_param_name(tape.index, j))
                )
        return tape

    def store(self, tape: LoopTape, k: Value, values: Iterable[Value]) -> None:
        """Store ``values`` in slot ``k``, guarded: past the tape's end, set the status."""
        b = self.b
        leaves = [leaf for v in values for leaf in self._flatten(v)]
        if not leaves:
            return
        cap = b.value("kd.array_shape", tape.params[0], dim=1)
        fits = b.value("arith.cmp", k, cap, pred="lt")
        then, other = Block(), Block()
        with b.at_end(then):
            for leaf, arr in zip(leaves, tape.params):
                b.create("kd.store", [leaf, arr, self.ltid, k])
            b.create("scf.yield", [])
        with b.at_end(other):
            b.create("kd.store", [b.constant(1, I32), self.status(), b.constant(0, I32)])
            b.create("scf.yield", [])
        b.create("scf.if", [fits], [], {TAPE_GUARD: tape.index},
                 regions=[Region(then), Region(other)])  # fmt: skip

    def record_trips(self, tape: LoopTape, slots: Value) -> None:
        """Nothing to do: the counting function sized the tapes."""

    def load(self, tape: LoopTape, k: Value, types: list[Type]) -> list[Value]:
        """Reload the values of ``types`` stored in slot ``k``."""
        leaves = [self.b.value("kd.load", arr, self.ltid, k) for arr in tape.params]
        return [self._unflatten(t, leaves) for t in types]

    def status(self) -> Value:
        """The hidden status array (added on first use)."""
        if self._status is None:
            self._status = self.body.add_arg(ArrayType(I32, 1), STATUS_PARAM)
        return self._status

    def finish(self, func: Operation) -> None:
        """Record the tape layout on the adjoint function for the runtime."""
        tapes = self.table.tapes
        if tapes:
            self.status()
        func.attrs["tape_leaves"] = [len(t.leaves) for t in tapes]
        func.attrs["tape_slots"] = [-1 if t.static_slots is None else t.static_slots for t in tapes]
        func.attrs["tape_sites"] = [t.site for t in tapes]

    def _flatten(self, v: Value) -> list[Value]:
        t = v.type
        if isinstance(t, StructType):
            return [leaf for fname, _ in t.fields
                    for leaf in self._flatten(self.b.value("struct.extract", v, field=fname))]  # fmt: skip
        if t == BOOL:
            return [self.b.create("arith.cast", [v], [I8]).result]
        return [v]

    def _unflatten(self, t: Type, leaves: list[Value]) -> Value:
        if isinstance(t, StructType):
            return self.b.create(
                "struct.construct", [self._unflatten(ft, leaves) for _, ft in t.fields], [t]
            ).result
        v = leaves.pop(0)
        if t == BOOL:
            return self.b.create("arith.cast", [v], [BOOL]).result
        return v
