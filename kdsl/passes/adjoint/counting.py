"""Tape counting: the function that measures the tapes a launch's adjoint needs.

A loop with constant bounds has a static tape size. Otherwise the adjoint pass
adds ``<kernel>__count``: the kernel's forward replay (its side effects removed)
with each taped loop's slot count reduced into ``tape_slots[tape]`` by an atomic
max. The runtime launches it on the same arguments first and allocates exactly
what the adjoint needs. Every loop that matters is counted at any depth, since a
nested loop's tape must hold its longest instance.
"""

from __future__ import annotations

from collections.abc import Iterable

from kdsl.ir import Builder, Operation, Value, new_func
from kdsl.ir.types import I32, ArrayType
from kdsl.passes.adjoint.analysis import Primal
from kdsl.passes.adjoint.replay import Replay
from kdsl.passes.adjoint.tapes import LoopTape, TapeTable

COUNT_SUFFIX = "__count"


class TripCounter:
    """The counting function's ``TapeSink``: stores nothing, records slot counts."""

    every_loop = True

    def __init__(self, table: TapeTable, b: Builder, counts: Value) -> None:
        self.table = table
        self.b = b
        self.counts = counts
        #: The tapes the adjoint made (``counts`` has one slot each). Replaying every
        #: loop, the counter may meet loops the adjoint never taped; it numbers them
        #: after these and records nothing for them (their slot would be out of range).
        self.known = len(table.tapes)

    def tape(self, op: Operation) -> LoopTape:
        """The tape the adjoint gave loop ``op``."""
        return self.table.lookup(op)[0]

    def store(self, tape: LoopTape, k: Value, values: Iterable[Value]) -> None:
        """Nothing to store: only the sizes are wanted."""

    def record_trips(self, tape: LoopTape, slots: Value) -> None:
        """Raise ``counts[tape]`` to ``slots`` when the tape is the adjoint's and its
        size is not static."""
        if tape.static_slots is None and tape.index < self.known:
            self.b.create("kd.atomic_rmw", [slots, self.counts, self.b.constant(tape.index, I32)],
                          attrs={"kind": "max"})  # fmt: skip


def build_counter(primal: Primal, table: TapeTable) -> Operation | None:
    """Add ``<kernel>__count`` after the adjoint filled ``table``; None if all sizes are static."""
    if table.all_static():
        return None
    args = primal.block.args
    func = new_func(
        primal.module, primal.sym + COUNT_SUFFIX, [a.type for a in args] + [ArrayType(I32, 1)],
        [a.name_hint for a in args] + ["tape_slots"], [], "kernel", primal.func.loc,
        {"counter_of": primal.sym},
    )  # fmt: skip
    body = func.regions[0].block
    vmap = {a: body.args[i] for i, a in enumerate(args)}
    b = Builder(body)
    Replay(primal, b, TripCounter(table, b, body.args[-1])).replay(primal.block, vmap, record=True)
    b.create("func.return", loc=primal.func.loc)
    return func
