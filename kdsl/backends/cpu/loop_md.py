"""LLVM loop metadata for the thread loop: its threads touch kernel arrays independently.

A kernel's threads run in no promised order (on the pool, in chunks, on a GPU, all at
once), so one thread's loads and stores of a kernel array never wait on another
thread's: a kernel in which thread ``p`` reads an element another thread writes
has no defined result. LLVM's loop vectorizer cannot see that: a thread loop that
reads ``x[q]`` at an index it loaded (a neighbour list) and writes ``out[p]`` might,
for all LLVM knows, read in one iteration what an earlier one wrote, and runtime
checks cannot cover a gathered index, so such loops stay scalar. The cloth scene's
spring kernel is one.

So each array load and store a kernel's thread body makes (``kd.load``,
``kd.store``, in ``memory``) carries the kernel's access group
(``!llvm.access.group``), and the thread loop's back edge carries
``llvm.loop.parallel_accesses`` naming it: the iterations' accesses in that group
are independent. LLVM treats the loop as parallel only when every memory access in
it is in the group; a thread that also touches memory another way (an atomic, a
thread-local array, a call left after inlining, ``print``) keeps the loop
sequential, as before. The vectorized code computes each thread in its own lane
with the same IEEE operations, so the results are the same bits.

Only arrays that are kernel parameters join the group: a thread-local array
(``kd.local_array``, one ``alloca`` the thread loop reuses) is shared by the
iterations, and so is anything reached through a record or a pointer.

For such a loop to vectorize it must be innermost: when every memory access of a
kernel is a load or store of a parameter array (``thread_parallel``), a loop inside
the thread with a constant trip count of at most ``UNROLL_INSIDE`` (``for s in
range(8)`` over a neighbour list) is emitted unrolled (``control``), as
``range(wp.static(8))`` would be.
"""

from __future__ import annotations

from typing import Any

from llvmlite import ir

from kdsl.ir.catalog import PURE, RECURSIVE_EFFECTS, TERMINATOR
from kdsl.ir.core import Operation, Value
from kdsl.ir.rewrite import constant_of

#: Loops inside a parallel thread body with a constant trip count up to this are emitted
#: unrolled, so the thread loop around them is innermost and can be vectorized.
UNROLL_INSIDE = 16
#: ... when the unrolled copies hold at most this many IR ops in all (compile time).
UNROLL_OPS = 2048


class _Distinct(ir.values.MDValue):
    """A metadata node printed ``distinct !{...}`` (access groups and loop ids must be)."""

    def descr(self, buf: list) -> None:
        buf.append("distinct ")
        super().descr(buf)


def _distinct(module: ir.Module, operands: list[Any], self_ref: bool = False) -> ir.MDValue:
    """A new distinct node of ``operands``, its own first operand when ``self_ref``."""
    node = _Distinct(module, module._fix_metadata_operands(operands), str(len(module.metadata)))
    if self_ref:
        node.operands = (node, *node.operands)
    return node


def access_group(module: ir.Module) -> ir.MDValue:
    """A new access group (a distinct node with no operands)."""
    return _distinct(module, [])


def mark_access(instructions: list[ir.Instruction], group: ir.MDValue | None) -> None:
    """Put the loads and stores among ``instructions`` into ``group`` (None: nothing)."""
    if group is None:
        return
    for ins in instructions:
        if isinstance(ins, ir.LoadInstr | ir.StoreInstr):
            ins.set_metadata("llvm.access.group", group)


def parallel_loop(module: ir.Module, group: ir.MDValue) -> ir.MDValue:
    """A loop id saying the accesses in ``group`` are independent across iterations."""
    return _distinct(module, [module.add_metadata(["llvm.loop.parallel_accesses", group])],
                     self_ref=True)  # fmt: skip


def short_trips(loop: Operation) -> int | None:
    """The trip count of ``scf.for`` ``loop`` when it is worth emitting unrolled: constant
    bounds and step, 1 to ``UNROLL_INSIDE`` trips, no loop inside it, and at most
    ``UNROLL_OPS`` ops in all the copies; else None."""
    if loop.name != "scf.for":
        return None
    bounds = [constant_of(v) for v in loop.operands[:3]]
    if not all(ok for ok, _ in bounds):
        return None
    lo, hi, step = (c for _, c in bounds)
    if step <= 0 or hi <= lo:
        return None
    trips = -(-(hi - lo) // step)
    inner = list(loop.walk())[1:]
    if trips > UNROLL_INSIDE or trips * len(inner) > UNROLL_OPS:
        return None
    return None if any(op.name in ("scf.for", "scf.while") for op in inner) else trips


_ARRAY_OPERAND = {"kd.load": 0, "kd.store": 1}


def thread_parallel(kernel: Operation) -> bool:
    """Whether every memory access in ``kernel``'s body is a load or store of one of its
    parameter arrays and nothing else has an effect (no atomic, call, print, local array)."""
    params = set(kernel.regions[0].block.args)
    for op in kernel.walk():
        if op is kernel:
            continue
        index = _ARRAY_OPERAND.get(op.name)
        if index is not None:
            if op.operands[index] not in params:
                return False
            continue
        traits = op.opdef.traits
        if not (PURE in traits or TERMINATOR in traits or RECURSIVE_EFFECTS in traits):
            return False
    return True


def kernel_arrays(kernel: Operation) -> frozenset[Value]:
    """``kernel``'s parameters: the arrays whose accesses join its access group."""
    return frozenset(kernel.regions[0].block.args)
