"""The forward replay: the kernel's values recomputed inside its adjoint.

The adjoint function first clones the kernel's ops, minus the effects the forward
launch already had (memory writes and output: the outputs hold them), except writes
into thread-local arrays, which it must redo (``local_arrays``). Checks are
replayed: they only stop a thread, and they guard the replayed reads as they
guarded the kernel's. Regions are cloned whole, except loops the reverse sweep
needs: those get an iteration counter and tape their carried values into a
``TapeSink`` (the tapes of the adjoint, or the trip counts of the counting
function).
"""

from __future__ import annotations

from kdsl.ir import Block, Builder, Operation, Region, Value
from kdsl.ir.catalog import CHECK, WRITES
from kdsl.ir.ops_local import LOCAL_ARRAY
from kdsl.ir.types import I32
from kdsl.passes.adjoint.analysis import Primal
from kdsl.passes.adjoint.local_arrays import local_base
from kdsl.passes.adjoint.tapes import TapeSink


def replays(op: Operation) -> bool:
    """Whether the forward replay repeats ``op`` (see the module docstring); writes into
    local arrays are decided by ``Replay`` (``local_arrays``)."""
    traits = op.opdef.traits
    return WRITES not in traits or CHECK in traits


class Replay:
    """Clones a kernel's ops at a builder, taping the loops that matter.

    ``trips`` maps each taped loop to its replayed trip count (the reverse sweep's
    loop bound).
    """

    def __init__(self, primal: Primal, b: Builder, sink: TapeSink) -> None:
        self.primal = primal
        self.b = b
        self.sink = sink
        self.trips: dict[Operation, Value] = {}
        #: Repeat every write into a local array (the forward replay and the counting
        #: function); once False (the reverse sweep's replays), only writes into local
        #: arrays the replay itself created (``fresh``), so no array is written twice.
        self.local_writes = True
        self.fresh: set[Value] = set()

    def replay(self, block: Block, vmap: dict[Value, Value], record: bool) -> list[Value]:
        """Clone ``block``'s ops at the builder (no side effects); give the terminator's operands.

        ``vmap`` maps the kernel's values to their clones and gains the new ones;
        with ``record``, loops that matter are taped.
        """
        for op in block.ops:
            if op.opdef.is_terminator:
                return [vmap[v] for v in op.operands]
            self.replay_op(op, vmap, record)
        return []

    def replay_op(self, op: Operation, vmap: dict[Value, Value], record: bool) -> None:
        """Clone one op (see ``replay``)."""
        name = op.name
        if not replays(op):
            base = local_base(op)
            if base is None or not (self.local_writes or base in self.fresh):
                return
        elif op.opdef is LOCAL_ARRAY:
            self.fresh.add(op.results[0])
        b = self.b
        with b.at(op.loc):
            if name == "scf.if":
                regions = [self._replay_region(r.block, vmap, []) for r in op.regions]
                new = b.create("scf.if", [vmap[op.operands[0]]], [r.type for r in op.results],
                               regions=regions)  # fmt: skip
            elif (
                name in ("scf.for", "scf.while")
                and (record or self.sink.every_loop)
                and self.primal.matters(op)
            ):
                self._replay_loop_taped(op, vmap)
                return
            elif name == "scf.for":
                body = op.regions[0].block
                region = self._replay_region(body, vmap, [a.type for a in body.args])
                new = b.create("scf.for", [vmap[v] for v in op.operands],
                               [r.type for r in op.results], regions=[region])  # fmt: skip
            elif name == "scf.while":
                before, after = op.regions
                regions = [
                    self._replay_region(before.block, vmap, [a.type for a in before.block.args]),
                    self._replay_region(after.block, vmap, [a.type for a in after.block.args]),
                ]
                new = b.create("scf.while", [vmap[v] for v in op.operands],
                               [r.type for r in op.results], regions=regions)  # fmt: skip
            else:
                attrs = dict(op.attrs)
                if name == "func.call":
                    callee = self.primal.callee(op)
                    attrs["callee"] = callee.attrs.get("custom_replay", attrs["callee"])
                new = Operation(op.opdef, [vmap[v] for v in op.operands],
                                [r.type for r in op.results], attrs, (), op.loc)  # fmt: skip
                b.insert(new)
        for old, r in zip(op.results, new.results):
            r.name_hint = old.name_hint
            vmap[old] = r

    def _replay_region(self, block: Block, vmap: dict[Value, Value], arg_types) -> Region:
        """A new region replaying ``block`` (its args become the new block's args)."""
        new = Block(arg_types, [a.name_hint for a in block.args])
        inner = dict(vmap)
        inner.update(zip(block.args, new.args))
        term = block.terminator
        with self.b.at_end(new):
            outs = self.replay(block, inner, record=False)
            self.b.create(term.name, outs, loc=term.loc)
        return Region(new)

    def _replay_loop_taped(self, op: Operation, vmap: dict[Value, Value]) -> None:
        """Replay a loop with an iteration counter ``k``, taping what it carries."""
        b = self.b
        tape = self.sink.tape(op)
        zero = b.constant(0, I32)
        one = b.constant(1, I32)
        if op.name == "scf.for":
            body = op.regions[0].block
            new_body = Block([a.type for a in body.args] + [I32],
                             [a.name_hint for a in body.args] + ["k"])  # fmt: skip
            inner = dict(vmap)
            inner.update(zip(body.args, new_body.args))
            k = new_body.args[-1]
            with b.at_end(new_body):
                self.sink.store(tape, k, new_body.args[1:-1])
                outs = self.replay(body, inner, record=False)
                b.create("scf.yield", [*outs, b.value("arith.add", k, one)])
            new = b.create(
                "scf.for",
                [vmap[v] for v in op.operands] + [zero],
                [r.type for r in op.results] + [I32],
                regions=[Region(new_body)],
            )
            slots = new.results[-1]
        else:
            before, after = op.regions[0].block, op.regions[1].block
            nb = Block([a.type for a in before.args] + [I32],
                       [a.name_hint for a in before.args] + ["k"])  # fmt: skip
            na = Block([a.type for a in after.args] + [I32],
                       [a.name_hint for a in after.args] + ["k"])  # fmt: skip
            inner = dict(vmap)
            inner.update(zip(before.args, nb.args))
            with b.at_end(nb):
                self.sink.store(tape, nb.args[-1], nb.args[:-1])
                outs = self.replay(before, inner, record=False)
                b.create("scf.condition", [*outs, nb.args[-1]])
            inner = dict(vmap)
            inner.update(zip(after.args, na.args))
            with b.at_end(na):
                outs = self.replay(after, inner, record=False)
                b.create("scf.yield", [*outs, b.value("arith.add", na.args[-1], one)])
            new = b.create(
                "scf.while",
                [vmap[v] for v in op.operands] + [zero],
                [r.type for r in op.results] + [I32],
                regions=[Region(nb), Region(na)],
            )
            slots = b.value("arith.add", new.results[-1], one)  # the before region ran N+1 times
        for old, r in zip(op.results, new.results):
            r.name_hint = old.name_hint
            vmap[old] = r
        self.trips[op] = new.results[-1]
        self.sink.record_trips(tape, slots)
