"""Lowering of ``kd.array_from_ptr`` (Warp's ``array(ptr=..., shape=...)`` in a kernel).

The descriptor holds the address, the extents (widened to 64 bits) and the contiguous
strides, which count scalar components (bytes for struct elements) as every cpu array
descriptor's do (``types``); they are products of the run-time extents.
"""

from __future__ import annotations

from llvmlite import ir

from kdsl.backends.cpu import types as LT
from kdsl.backends.cpu.emitter import Emitter
from kdsl.ir import types as T
from kdsl.ir.core import Operation
from kdsl.ir.lowering import LOWERINGS

CPU = LOWERINGS.for_backend("cpu")


def _array_from_ptr(em: Emitter, op: Operation) -> ir.Value:
    t: T.ArrayType = op.results[0].type
    B = em.b
    dt = T.storage_dtype(t.dtype)
    unit = 1 if isinstance(t.dtype, T.StructType) else T.elem_type(t.dtype).np_dtype.itemsize
    dims = [B.sext(em.get(d), LT.I64) for d in op.operands[1:]]
    desc = ir.Constant(LT.descriptor_type(t.ndim), ir.Undefined)
    desc = B.insert_value(desc, B.inttoptr(em.get(op.operands[0]), LT.PTR), 0)
    step: ir.Value = ir.Constant(LT.I64, dt.itemsize // unit)
    for d in reversed(range(t.ndim)):
        desc = B.insert_value(desc, dims[d], [1, d])
        desc = B.insert_value(desc, step, [2, d])
        step = B.mul(step, dims[d])
    return desc


CPU.register("kd.array_from_ptr", _array_from_ptr)
