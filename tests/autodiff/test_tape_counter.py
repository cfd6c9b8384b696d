"""The tape-counting function records slot counts only for the adjoint's own tapes.

Replaying every loop, the counter may meet loops the adjoint never taped (a loop whose
values no gradient needs, as ``mesh_query_point_sign_parity``'s rays in a kernel that
also holds other queries). Such a loop gets a tape number past the adjoint's, and a
count written there fell outside ``tape_slots`` (an out-of-bounds atomic on cpu)."""

from __future__ import annotations

import kdsl as wp
from kdsl.ir import Builder
from kdsl.ir.types import I32, ArrayType
from kdsl.passes.adjoint.counting import TripCounter
from kdsl.passes.adjoint.tapes import TapeTable


@wp.kernel
def two_loops(xs: wp.array(dtype=float), n: int, out: wp.array(dtype=float)):
    i = wp.tid()
    a = xs[i]
    for _j in range(n):
        a = a * 2.0
    b = xs[i]
    while b < 10.0:
        b = b + 1.0
    out[i] = a + b


def _loops():
    m = two_loops.build_module()
    func = next(f for f in m.funcs if f.attrs["sym_name"].startswith("two_loops"))
    loops = [op for op in func.walk() if op.name in ("scf.for", "scf.while")]
    assert len(loops) == 2
    return func, loops


def test_a_loop_the_adjoint_did_not_tape_is_not_counted():
    func, (first, second) = _loops()
    table = TapeTable("two_loops")
    adjoint_tape, _ = table.lookup(first)  # the adjoint taped the first loop only
    body = func.regions[0].block
    counts = body.add_arg(ArrayType(I32, 1), "tape_slots")
    b = Builder(body)
    counter = TripCounter(table, b, counts)
    slots = b.constant(3, I32)
    before = len(body.ops)
    extra = counter.tape(second)
    assert extra.index == 1  # numbered after the adjoint's tapes
    counter.record_trips(extra, slots)
    assert len(body.ops) == before  # nothing written for it
    counter.record_trips(adjoint_tape, slots)
    atomics = [op for op in body.ops[before:] if op.name == "kd.atomic_rmw"]
    assert len(atomics) == 1 and atomics[0].operands[1] is counts
