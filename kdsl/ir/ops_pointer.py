"""``kd.array_from_ptr``: an array made in a kernel from a raw address (Warp's ``array``).

``array(ptr=p, shape=(n, m), dtype=float)`` in a Warp kernel wraps the memory at the
``uint64`` address ``p`` as a contiguous array of that shape. The op takes the address
and one ``i32`` extent per dimension and gives the array descriptor; the strides are
the contiguous ones for the element type. Nothing is checked or owned: the address
must point at enough memory of the running device for as long as the array is used
(as in Warp). It reads no memory itself, so it is pure.
"""

from __future__ import annotations

from kdsl.errors import KdslRuntimeError
from kdsl.ir.catalog import CATALOG, PURE
from kdsl.ir.core import Operation
from kdsl.ir.ops_local import dense_strides
from kdsl.ir.records import array_from_words
from kdsl.ir.types import I32, U64, ArrayType, HandleType


def _verify(op: Operation) -> None:
    res = op.results[0].type if len(op.results) == 1 else None
    if not isinstance(res, ArrayType) or isinstance(res.dtype, ArrayType | HandleType):
        raise TypeError("kd.array_from_ptr gives one array of values")
    if not op.operands or op.operands[0].type != U64:
        raise TypeError("kd.array_from_ptr takes a uint64 address first")
    dims = op.operands[1:]
    if len(dims) != res.ndim or any(d.type != I32 for d in dims):
        raise TypeError(f"kd.array_from_ptr takes one i32 extent per dimension ({res.ndim})")


def _interp(ctx, op: Operation, ptr, *dims):
    t: ArrayType = op.results[0].type
    shape = [int(d) for d in dims]
    if any(n < 0 for n in shape):
        raise KdslRuntimeError(f"array(): negative extent in shape {tuple(shape)}")
    return array_from_words(t, [int(ptr), *shape, *dense_strides(t, tuple(shape), 1)])


ARRAY_FROM_PTR = CATALOG.define(
    "kd.array_from_ptr",
    "A contiguous array over the memory at uint64 address ``ptr`` with the given extents "
    "(Warp's ``array(ptr=..., shape=..., dtype=...)`` in a kernel). Nothing is owned or "
    "checked: the memory must hold the elements for as long as the array is used.",
    traits=frozenset({PURE}), verifier=_verify, interp=_interp,
    folder=lambda op, values: None,  # an address is a run-time value
    example="%2 = kd.array_from_ptr %0, %1 : array<f32, 1>", group="memory",
)  # fmt: skip
