"""Lowering of ``kd.local_array`` (a thread-local array) to an ``alloca``.

The storage is one ``alloca`` in the function's entry block, whatever loop or branch
the op sits in: LLVM's SROA/mem2reg promote only entry-block allocas, so a small local
array indexed by constants (after unrolling) becomes registers, and the thread loop
does not grow the stack on each iteration. Each run of the op zero-fills the storage
with ``llvm.memset`` where the op is (not with ``fill = "none"``: the contents are
undefined until written, ``kdsl.ext.empty``), then builds the descriptor over it: strides
count scalar elements (bytes for struct elements), as every array descriptor's do
(``types``), so the memory ops work on it unchanged.
"""

from __future__ import annotations

import math

from llvmlite import ir

from kdsl.backends.cpu import types as LT
from kdsl.backends.cpu.emitter import Emitter
from kdsl.ir import types as T
from kdsl.ir.core import Operation
from kdsl.ir.lowering import LOWERINGS
from kdsl.ir.ops_local import dense_strides, fill_of

CPU = LOWERINGS.for_backend("cpu")


def _storage(t: T.ArrayType, shape: tuple[int, ...]) -> tuple[ir.Type, int, int]:
    """(LLVM storage type, bytes, stride unit in bytes) of a dense array of ``t``."""
    dt = T.storage_dtype(t.dtype)
    nbytes = math.prod(shape) * dt.itemsize
    if isinstance(t.dtype, T.StructType):
        return ir.ArrayType(LT.I8, nbytes), nbytes, 1
    et = T.elem_type(t.dtype)
    unit = et.np_dtype.itemsize
    return ir.ArrayType(LT.memory_scalar(et), nbytes // unit), nbytes, unit


def _local_array(em: Emitter, op: Operation) -> ir.Value:
    t: T.ArrayType = op.results[0].type
    shape = tuple(op.attrs["shape"])
    storage, nbytes, unit = _storage(t, shape)
    align = max(16, T.storage_dtype(t.dtype).alignment)
    entry = ir.IRBuilder(em.fn.entry_basic_block)
    entry.position_at_start(em.fn.entry_basic_block)
    ptr = entry.alloca(storage, name=op.results[0].name_hint or "local")
    ptr.align = align
    B = em.b
    if fill_of(op) == "zero":
        memset = em.intrinsic(
            "llvm.memset", [LT.PTR, LT.I64], LT.VOID, [LT.PTR, LT.I8, LT.I64, LT.I1]
        )
        zero, size = ir.Constant(LT.I8, 0), ir.Constant(LT.I64, nbytes)
        B.call(memset, [ptr, zero, size, ir.Constant(LT.I1, 0)])
    desc = ir.Constant(LT.descriptor_type(t.ndim), ir.Undefined)
    desc = B.insert_value(desc, ptr, 0)
    for d, (n, s) in enumerate(zip(shape, dense_strides(t, shape, unit))):
        desc = B.insert_value(desc, ir.Constant(LT.I64, n), [1, d])
        desc = B.insert_value(desc, ir.Constant(LT.I64, s), [2, d])
    return desc


CPU.register("kd.local_array", _local_array)
