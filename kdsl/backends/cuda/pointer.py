"""Lowering of ``kd.array_from_ptr`` (Warp's ``array(ptr=..., shape=...)`` in a kernel).

The descriptor (``kd_array<N>``: data, extents, byte strides) over the address, with
the contiguous strides computed from the run-time extents by a small helper.
"""

from __future__ import annotations

from kdsl.backends.cuda.emitter import FuncEmitter
from kdsl.ir import types as T
from kdsl.ir.core import Operation
from kdsl.ir.lowering import LOWERINGS

CUDA = LOWERINGS.for_backend("cuda")


def _array_from_ptr(em: FuncEmitter, op: Operation) -> str:
    t: T.ArrayType = op.results[0].type
    src = em.src
    out = src.ctype(t)
    size = T.storage_dtype(t.dtype).itemsize
    name = f"kd_from_ptr_{out}_{size}"
    nd = t.ndim
    params = ", ".join(f"long long n{d}" for d in range(nd))
    strides = ", ".join(
        " * ".join([f"{size}LL", *(f"n{k}" for k in range(d + 1, nd))]) for d in range(nd)
    )
    shape = ", ".join(f"n{d}" for d in range(nd))
    src.need(
        name,
        lambda: (
            f"__device__ __forceinline__ {out} {name}(unsigned long long p, {params}) {{ "
            f"return {out}{{(char *)p, {{{shape}}}, {{{strides}}}}}; }}"
        ),
    )
    args = ", ".join(em.get(v) for v in op.operands)
    return f"{name}({args})"


CUDA.register("kd.array_from_ptr", _array_from_ptr)
