"""Lowering of ``kd.prefetch`` (``kdsl.ir.ops_prefetch``): ``llvm.prefetch`` of each
64-byte line the element may touch, for reading, kept in all cache levels."""

from __future__ import annotations

from llvmlite import ir

from kdsl.backends.cpu import types as LT
from kdsl.backends.cpu.emitter import Emitter
from kdsl.backends.cpu.memory import element_ptr
from kdsl.ir.core import Operation
from kdsl.ir.lowering import LOWERINGS
from kdsl.ir.types import storage_dtype

CPU = LOWERINGS.for_backend("cpu")

#: The cache line size prefetches are spaced by (x86-64 and most arm64 cores).
LINE = 64


def line_offsets(size: int) -> list[int]:
    """Byte offsets within an element of ``size`` bytes that reach every line it may
    touch, whatever its alignment: one per ``LINE`` bytes and its last byte."""
    offsets = list(range(0, size, LINE))
    if size - 1 > offsets[-1]:
        offsets.append(size - 1)
    return offsets


def _prefetch(em: Emitter, op: Operation) -> None:
    at = op.operands[0].type
    ptr = element_ptr(em, em.get(op.operands[0]), at, op.operands[1:])
    fn = em.state.declare(
        "llvm.prefetch.p0", ir.FunctionType(ir.VoidType(), [ptr.type, LT.I32, LT.I32, LT.I32])
    )
    read, keep, data = (ir.Constant(LT.I32, v) for v in (0, 3, 1))
    for off in line_offsets(storage_dtype(at.dtype).itemsize):
        at_line = em.b.gep(ptr, [ir.Constant(LT.I64, off)], inbounds=False, source_etype=LT.I8)
        em.b.call(fn, [at_line, read, keep, data])


CPU.register("kd.prefetch", _prefetch)
