"""Range-local sums: atomic adds to one element from every thread, summed per range.

A kernel that adds into the same element from every thread (a loss, a total, the
adjoint of a parameter that every thread reads) pays for one atomic
read-modify-write per thread. On x86 a float atomic add is a compare-and-swap loop,
about 15 ns each on one thread (the ``throw`` scene's loss: 62 us for 4,096 threads
against 13 us for its whole flight step), and on the thread pool every thread fights
for the same cache line, so splitting the range gains nothing.

When the element does not depend on the thread and nothing else in the kernel
touches the array, a range function (one pool chunk, or the whole launch inline)
adds into a local accumulator instead, and adds its sum to memory with one atomic
after its range: one atomic per chunk. ``find_sites`` picks the atomics this is
exact for: ``atomic_add`` (kind ``add``) whose old value is unused, into a kernel
parameter array of integers or of float32/float64 scalars, vectors or matrices,
at an index made of kernel parameters and constants, where every use of that array
in the kernel is such an atomic add. Debug builds keep one atomic per thread (their
bounds checks report the thread).

Integer sums are unchanged (integer addition is associative). Float sums are
rounded in another order: memory ``m`` and terms ``a0, a1, ...`` of one range give
``m + ((a0 + a1) + ...)`` in place of ``((m + a0) + a1) + ...``. kdsl promises no
order for float atomics on the cpu (the ``deterministic`` module option refuses
ordered modes), and the result is still the same from run to run for one thread
count; a launch that starts from ``m = 0`` on one thread gives the very same
bits as before. The accumulator starts at ``-0.0`` (``x + -0.0 == x`` for every
``x``, zeros' signs included), and the range adds its sum only when its site ran,
so a range that never reaches the atomic leaves memory untouched.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from llvmlite import ir

from kdsl.backends.cpu import types as LT
from kdsl.backends.cpu.composite import Parts
from kdsl.ir import types as T
from kdsl.ir.core import Block, Operation


def _summable(op: Operation, params: set, index: int) -> bool:
    """Whether ``op`` (a use of a parameter array at operand ``index``) is an atomic add
    of an unused old value at a thread-independent index, of a type summed exactly."""
    if op.name != "kd.atomic_rmw" or index != 1 or op.attrs.get("kind") != "add":
        return False
    if any(r.uses for r in op.results):
        return False
    t = op.operands[1].type.dtype
    if not isinstance(t, T.ScalarType | T.VectorType | T.MatrixType):
        return False
    et = T.elem_type(t)
    if et.is_bool or (et.is_float and et.bits not in (32, 64)):
        return False
    return all(
        v in params or (getattr(v, "op", None) is not None and v.op.name == "arith.constant")
        for v in op.operands[2:]
    )


def find_sites(block: Block) -> list[Operation]:
    """The atomic adds of kernel body ``block`` that may sum per range (module
    docstring), in program order."""
    params = set(block.args)
    sites: set[Operation] = set()
    for arg in block.args:
        if not isinstance(arg.type, T.ArrayType):
            continue
        uses = list(arg.uses)
        if uses and all(_summable(op, params, index) for op, index in uses):
            sites.update(op for op, _ in uses)
    return [op for top in block.ops for op in top.walk() if op in sites]


class LocalSums:
    """The accumulators of one range function's sites: per site, one local per component
    and the components' addresses (null until the site first runs)."""

    def __init__(self, builder: ir.IRBuilder, sites: Sequence[Operation]) -> None:
        """Allocate and initialize the accumulators where ``builder`` is (the entry block)."""
        self.sites: dict[Operation, tuple[list[ir.Value], list[ir.Value], bool]] = {}
        for op in sites:
            t = op.operands[1].type.dtype
            et = T.elem_type(t)
            lt = LT.memory_scalar(et)
            zero = ir.Constant(lt, -0.0) if et.is_float else ir.Constant(lt, 0)
            sums, addrs = [], []
            for _ in range(LT.count(t)):
                s = builder.alloca(lt)
                builder.store(zero, s)
                a = builder.alloca(LT.PTR)
                builder.store(ir.Constant(LT.PTR, None), a)
                sums.append(s)
                addrs.append(a)
            self.sites[op] = (sums, addrs, et.is_float)

    def __contains__(self, op: Operation) -> bool:
        return op in self.sites

    def add(self, builder: ir.IRBuilder, op: Operation, ptrs: Sequence[ir.Value],
            values: Sequence[ir.Value]) -> Any:  # fmt: skip
        """Add ``values`` (the components) into ``op``'s accumulators, remembering the
        components' addresses ``ptrs``; gives a placeholder for the unused old value."""
        sums, addrs, is_float = self.sites[op]
        out = []
        for s, a, p, x in zip(sums, addrs, ptrs, values):
            builder.store(p, a)
            old = builder.load(s)
            builder.store(builder.fadd(old, x) if is_float else builder.add(old, x), s)
            out.append(old)
        return out[0] if len(out) == 1 else Parts(out)

    def flush(self, builder: ir.IRBuilder, fn: ir.Function) -> None:
        """After the range: one atomic add of each accumulator whose site ran."""
        for sums, addrs, is_float in self.sites.values():
            for s, a in zip(sums, addrs):
                ptr = builder.load(a)
                ran = builder.icmp_unsigned("!=", ptr, ir.Constant(LT.PTR, None))
                then, done = fn.append_basic_block("sum.flush"), fn.append_basic_block("sum.done")
                builder.cbranch(ran, then, done)
                builder.position_at_end(then)
                builder.atomic_rmw("fadd" if is_float else "add", ptr, builder.load(s),
                                   "monotonic")  # fmt: skip
                builder.branch(done)
                builder.position_at_end(done)
