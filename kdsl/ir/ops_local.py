"""``kd.local_array``: a zero-filled array private to one thread (Warp's ``fixedarray``).

Its value is an ordinary array descriptor (pointer, shape, strides) over memory that
belongs to the running thread, so every memory op (``kd.load``, ``kd.store``, the
atomics, ``kd.array_view``, ``kd.array_shape``) and every function taking an array
works on it unchanged. The shape is an attribute: it must be known when the kernel is
compiled, which lets the backends place the storage on the stack (cpu: an ``alloca``
in the function's entry block, which LLVM promotes to registers when every index is
constant; cuda: a C local array). Each time the op runs it gives fresh zeros.

The op is not pure (two local arrays of one shape are two memories, never merged by
CSE) but has no effect other than producing new memory, so it carries ``READS``: DCE
removes one nobody uses, and the adjoint's forward replay repeats it.
"""

from __future__ import annotations

import math

import numpy as np

from kdsl.ir.catalog import CATALOG, READS
from kdsl.ir.types import ArrayType, HandleType, Type, storage_dtype

#: The largest local array, in bytes. A thread's stack (cpu) and its local memory
#: (cuda) are small and slow to spill into: larger scratch belongs in a global array.
MAX_LOCAL_BYTES = 64 * 1024


def local_array_error(dtype: Type, shape: tuple[int, ...]) -> str | None:
    """Why a local array of ``dtype`` and ``shape`` cannot exist, or None if it can."""
    if not 1 <= len(shape) <= 4:
        return f"a local array has 1 to 4 dimensions, not {len(shape)}"
    if any(not isinstance(n, int) or isinstance(n, bool) or n < 1 for n in shape):
        return f"a local array's shape holds positive integers, not {tuple(shape)}"
    if isinstance(dtype, ArrayType | HandleType):
        return f"a local array cannot hold values of type {dtype}"
    try:
        itemsize = storage_dtype(dtype).itemsize
    except TypeError:
        return f"a local array cannot hold values of type {dtype}"
    size = math.prod(shape) * itemsize
    if size > MAX_LOCAL_BYTES:
        return (
            f"a local array of shape {tuple(shape)} and type {dtype} takes {size} bytes, over "
            f"the limit of {MAX_LOCAL_BYTES} bytes per thread; use a global array instead"
        )
    return None


def _verify(op) -> None:
    (res,) = op.results
    if op.operands:
        raise TypeError("kd.local_array takes no operands")
    if not isinstance(res.type, ArrayType):
        raise TypeError(f"kd.local_array gives an array, not {res.type}")
    shape = op.attrs["shape"]
    if not isinstance(shape, list | tuple) or len(shape) != res.type.ndim:
        raise TypeError(f"kd.local_array shape {shape!r} does not match {res.type}")
    why = local_array_error(res.type.dtype, tuple(shape))
    if why is not None:
        raise TypeError(why)


def _interp(ctx, op):
    t: ArrayType = op.results[0].type
    return np.zeros(tuple(op.attrs["shape"]), dtype=storage_dtype(t.dtype))


def dense_strides(t: ArrayType, shape: tuple[int, ...], unit: int) -> list[int]:
    """Row-major strides of a dense array of ``t`` with ``shape``, in units of ``unit`` bytes."""
    step = storage_dtype(t.dtype).itemsize // unit
    out = []
    for n in reversed(shape):
        out.append(step)
        step *= n
    return out[::-1]


def is_local_array(v) -> bool:
    """Whether the value ``v`` is a ``kd.local_array`` result."""
    op = getattr(v, "op", None)
    return op is not None and op.opdef is LOCAL_ARRAY


LOCAL_ARRAY = CATALOG.define(
    "kd.local_array",
    "A zero-filled array of constant ``shape`` private to the running thread (Warp's "
    "``zeros(shape, dtype)`` in a kernel, a ``fixedarray``): an ordinary array value, so "
    "every memory op and every function taking an array accept it. Each run of the op "
    f"gives fresh zeros. At most {MAX_LOCAL_BYTES} bytes.",
    traits=frozenset({READS}), verifier=_verify, interp=_interp, required_attrs=("shape",),
    example="%0 = kd.local_array {shape = [8]} : array<f32, 1>", group="memory",
)  # fmt: skip

__all__ = ["LOCAL_ARRAY", "MAX_LOCAL_BYTES", "dense_strides", "is_local_array",
           "local_array_error"]  # fmt: skip
