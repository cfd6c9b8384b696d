"""The ``kd`` dialect: thread indices, array shapes, loads, stores and atomics.

Arrays are memory. Reads and writes go through these ops, which carry effects;
every other value is an immutable SSA value. Indices are integers, one per array
dimension. An index out of range is an error: the interpreter always checks, the
compiled backends check in debug mode.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from kdsl.errors import KdslRuntimeError
from kdsl.ir import semantics as sem
from kdsl.ir.catalog import CATALOG, PURE, READS, SPECULATABLE, WRITES
from kdsl.ir.core import Operation
from kdsl.ir.types import (
    I32,
    ArrayType,
    ScalarType,
    StructType,
    Type,
    elem_type,
    storage_dtype,
    value_shape,
)

ATOMIC_KINDS = ("add", "sub", "min", "max", "and", "or", "xor", "exch")


def _tid_verify(op) -> None:
    dim, ndim = op.attrs["dim"], op.attrs["ndim"]
    if not (1 <= ndim <= 4 and 0 <= dim < ndim):
        raise TypeError(f"kd.tid dim={dim} ndim={ndim} is out of range (ndim is 1 to 4)")
    if op.results[0].type != I32:
        raise TypeError("kd.tid gives an i32")


def _tid_interp(ctx, op):
    return ctx.tid(op.attrs["dim"], op.attrs["ndim"])


TID = CATALOG.define(
    "kd.tid",
    "Index of the running thread. With ``ndim = 1`` it is the linear index over the "
    "whole launch; with ``ndim = n`` (the launch must have n dimensions) it is "
    "component ``dim`` of the n-dimensional index.",
    traits=frozenset({PURE, SPECULATABLE}), verifier=_tid_verify, interp=_tid_interp,
    required_attrs=("dim", "ndim"), example="%0 = kd.tid {dim = 0, ndim = 1} : i32", group="memory",
)  # fmt: skip


BLOCK_DIM = CATALOG.define(
    "kd.block_dim",
    "Number of threads of the running thread's block: the block size of the launch on "
    "cuda, 1 on the cpu backend and the interpreter (as Warp on the CPU).",
    traits=frozenset({PURE, SPECULATABLE}), type_rule=lambda ts, attrs: [I32],
    interp=lambda ctx, op: np.int32(1), example="%0 = kd.block_dim : i32", group="memory",
)  # fmt: skip


def _shape_rule(ts: Sequence[Type], attrs: dict[str, Any]) -> list[Type]:
    (a,) = ts
    if not isinstance(a, ArrayType):
        raise TypeError(f"only arrays have a shape, not {a}")
    dim = attrs.get("dim")
    if not isinstance(dim, int) or not 0 <= dim < a.ndim:
        raise TypeError(f"shape[{dim}] is out of range for a {a.ndim}-d array")
    return [I32]


ARRAY_SHAPE = CATALOG.define(
    "kd.array_shape", "Extent of dimension ``dim`` of an array.",
    traits=frozenset({PURE, SPECULATABLE}), type_rule=_shape_rule,
    interp=lambda ctx, op, a: np.int32(a.shape[op.attrs["dim"]]), required_attrs=("dim",),
    example="%1 = kd.array_shape %0 {dim = 0} : i32", group="memory",
)  # fmt: skip


def check_access(
    a: Type,
    idx: Sequence[Type],
    what: str = "only arrays can be indexed this way",
    partial: bool = False,
) -> ArrayType:
    """``a`` as an array that the index types ``idx`` address one element of.

    With ``partial``, 1 to ``ndim`` leading indices are accepted (a view's or a
    bounds check's). Raises ``TypeError`` otherwise; ``what`` begins the message for
    a non-array.
    """
    if not isinstance(a, ArrayType):
        raise TypeError(f"{what}, not {a}")
    if partial and not 1 <= len(idx) <= a.ndim:
        raise TypeError(
            f"a {a.ndim}-d array needs {a.ndim} indices (or fewer, for a view), got {len(idx)}"
        )
    if not partial and len(idx) != a.ndim:
        raise TypeError(f"a {a.ndim}-d array needs {a.ndim} indices, got {len(idx)}")
    for t in idx:
        if not (isinstance(t, ScalarType) and t.is_int):
            raise TypeError(f"an array index must be an integer, not {t}")
    return a


def _load_rule(ts: Sequence[Type], attrs: dict[str, Any]) -> list[Type]:
    return [check_access(ts[0], ts[1:]).dtype]


def element_index(ctx, op, arr: np.ndarray, array_operand: int, idx: Sequence[Any]) -> tuple:
    """Bounds-checked element index: raises a ``KdslRuntimeError`` naming it all."""
    at: ArrayType = op.operands[array_operand].type
    shape = arr.shape[: at.ndim]
    ix = tuple(int(i) for i in idx)
    for i, n in zip(ix, shape):
        if not 0 <= i < n:
            name = op.operands[array_operand].name_hint or "array"
            kernel = getattr(ctx, "kernel_name", "?")
            raise KdslRuntimeError(
                f"index {list(ix)} is out of bounds for array '{name}' of shape "
                f"{tuple(shape)} in kernel '{kernel}'",
                op.loc,
                kernel,
            )
    return ix


def to_value(raw: Any, t: Type) -> Any:
    """An element read from a NumPy array, as the interpreter's value of type ``t``."""
    if isinstance(t, StructType):
        return tuple(to_value(raw[name], ft) for name, ft in t.fields)
    if isinstance(raw, np.ndarray):
        return raw.copy()
    return raw


def from_value(value: Any, t: Type) -> Any:
    """The interpreter's value of type ``t`` as something NumPy can store."""
    if isinstance(t, StructType):
        return tuple(from_value(v, ft) for v, (_, ft) in zip(value, t.fields))
    return value


def _load_interp(ctx, op, a, *idx):
    ix = element_index(ctx, op, a, 0, idx)
    return to_value(a[ix], op.results[0].type)


LOAD = CATALOG.define(
    "kd.load", "Read one element of an array.",
    traits=frozenset({READS}), type_rule=_load_rule, interp=_load_interp, array_operand=0,
    example="%2 = kd.load %0, %1 : f32", group="memory",
)  # fmt: skip


def _view_rule(ts: Sequence[Type], attrs: dict[str, Any]) -> list[Type]:
    a = check_access(ts[0], ts[1:], "only arrays have views", partial=True)
    if len(ts) - 1 >= a.ndim:
        raise TypeError(
            f"a view of a {a.ndim}-d array takes fewer than {a.ndim} indices, got {len(ts) - 1}"
        )
    return [ArrayType(a.dtype, a.ndim - (len(ts) - 1))]


def _view_interp(ctx, op, a, *idx):
    ix = element_index(ctx, op, a, 0, idx)
    return a[ix]  # a NumPy view: stores through it reach the array


ARRAY_VIEW = CATALOG.define(
    "kd.array_view",
    "The sub-array at leading indices ``i...`` (fewer than the array's dims): an array "
    "of the remaining dims that shares the memory, as ``a[i]`` on a 2-d array in Warp. "
    "Its data pointer is the address of ``a[i..., 0...]``; shape and strides are the "
    "array's last ones. The indices must be in range (checked like an access).",
    traits=frozenset({PURE}), type_rule=_view_rule, interp=_view_interp,
    example="%2 = kd.array_view %0, %1 : array<f32, 1>", group="memory",
)  # fmt: skip


def _null_array_interp(ctx, op):
    t: ArrayType = op.results[0].type
    if isinstance(t.dtype, StructType):
        return np.zeros((0,) * t.ndim, dtype=storage_dtype(t.dtype))
    return np.zeros((0,) * t.ndim + value_shape(t.dtype), dtype=elem_type(t.dtype).np_dtype)


def _verify_null_array(op: Operation) -> None:
    if op.operands or len(op.results) != 1 or not isinstance(op.results[0].type, ArrayType):
        raise TypeError("kd.null_array takes no operands and gives one array")


NULL_ARRAY = CATALOG.define(
    "kd.null_array",
    "An array with no elements (null data, every dim 0): what an array field holds in a "
    "zero adjoint of a struct (adjoints of arrays are never read).",
    traits=frozenset({PURE, SPECULATABLE}), verifier=_verify_null_array,
    interp=_null_array_interp, example="%0 = kd.null_array : array<f32, 1>", group="memory",
)  # fmt: skip


def _store_rule(ts: Sequence[Type], attrs: dict[str, Any]) -> list[Type]:
    v, a = ts[0], ts[1]
    at = check_access(a, ts[2:])
    if v != at.dtype:
        raise TypeError(f"cannot store a {v} into an array of {at.dtype}")
    return []


def _store_interp(ctx, op, v, a, *idx):
    ix = element_index(ctx, op, a, 1, idx)
    a[ix] = from_value(v, op.operands[0].type)


STORE = CATALOG.define(
    "kd.store", "Write a value into one element of an array: ``kd.store %value, %array, %i...``.",
    traits=frozenset({WRITES}), type_rule=_store_rule, interp=_store_interp,
    array_operand=1, stored_operand=0, example="kd.store %2, %0, %1", group="memory",
)  # fmt: skip


def _atomic_rule(ts: Sequence[Type], attrs: dict[str, Any]) -> list[Type]:
    kind = attrs.get("kind")
    if kind not in ATOMIC_KINDS:
        raise TypeError(f"unknown atomic kind {kind!r}")
    v, a = ts[0], ts[1]
    at = check_access(a, ts[2:])
    if v != at.dtype:
        raise TypeError(f"cannot atomically {kind} a {v} into an array of {at.dtype}")
    et = elem_type(v)
    if kind in ("and", "or", "xor") and not et.is_int:
        raise TypeError(f"atomic {kind} needs an integer array, not {at.dtype}")
    return [v]


_ATOMIC_FNS = {
    "add": np.add, "sub": np.subtract, "min": sem.float_min, "max": sem.float_max,
    "and": np.bitwise_and, "or": np.bitwise_or, "xor": np.bitwise_xor,
    "exch": lambda old, new: new,
}  # fmt: skip


def _atomic_interp(ctx, op, v, a, *idx):
    ix = element_index(ctx, op, a, 1, idx)
    old = to_value(a[ix], op.results[0].type)
    with np.errstate(all="ignore"):
        new = _ATOMIC_FNS[op.attrs["kind"]](np.asarray(old), np.asarray(v))
    a[ix] = sem.unwrap(np.asarray(new).astype(np.asarray(old).dtype))
    return old


ATOMIC_RMW = CATALOG.define(
    "kd.atomic_rmw",
    "Atomic read-modify-write of one array element with ``kind`` (add, sub, min, "
    "max, and, or, xor, exch); gives the old value. Vectors and matrices work "
    "componentwise (each component is one atomic update). Integers wrap; float "
    "min/max follow ``arith.min``/``arith.max`` (NaN loses, -0.0 < +0.0).",
    traits=frozenset({READS, WRITES}), type_rule=_atomic_rule, interp=_atomic_interp,
    array_operand=1, stored_operand=0, required_attrs=("kind",), group="memory",
    example='%3 = kd.atomic_rmw %2, %0, %1 {kind = "add"} : f32',
)  # fmt: skip


def _cas_rule(ts: Sequence[Type], attrs: dict[str, Any]) -> list[Type]:
    compare, v, a = ts[0], ts[1], ts[2]
    at = check_access(a, ts[3:])
    if v != at.dtype or compare != at.dtype:
        raise TypeError(
            f"atomic cas needs a compare value and a new value of the array's type "
            f"{at.dtype}, got {compare} and {v}"
        )
    return [v]


def _bits(x: np.ndarray) -> np.ndarray:
    """The raw bits of ``x`` as unsigned integers of the same width."""
    x = np.array(x)  # a contiguous copy that keeps 0-d values 0-d
    return x.view(np.dtype(f"u{x.dtype.itemsize}"))


def _cas_interp(ctx, op, compare, v, a, *idx):
    ix = element_index(ctx, op, a, 2, idx)
    t = op.results[0].type
    old = to_value(a[ix], t)
    old_arr, new_arr = np.array(old), np.array(v, dtype=np.asarray(old).dtype)
    same = _bits(old_arr) == _bits(np.array(compare, dtype=old_arr.dtype))
    a[ix] = sem.unwrap(np.where(same, new_arr, old_arr))
    return old


ATOMIC_CAS = CATALOG.define(
    "kd.atomic_cas",
    "Atomic compare-and-swap of one array element: ``kd.atomic_cas %compare, %value, "
    "%array, %i...`` stores ``value`` where the element's bits equal ``compare``'s and "
    "gives the old value. Floats compare by bits (NaN can match, -0.0 does not match "
    "+0.0), as the hardware does. Vectors and matrices work componentwise.",
    traits=frozenset({READS, WRITES}), type_rule=_cas_rule, interp=_cas_interp,
    array_operand=2,  # writes only where the compare matches: no stored_operand
    example="%4 = kd.atomic_cas %2, %3, %0, %1 : i32", group="memory",
)  # fmt: skip


FENCE = CATALOG.define(
    "kd.fence",
    "A sequentially consistent memory fence across the whole launch (CUDA's "
    "``__threadfence``, LLVM's ``fence seq_cst``): the thread's reads and writes before it "
    "are ordered before those after it as every thread of the launch sees them. A thread "
    "that writes, fences, then bumps an atomic counter publishes its writes to the thread "
    "that reads the counter's new value and then fences (the bottom-up pattern of BVH "
    "refits). The interpreter runs threads one at a time, so it needs no fence.",
    traits=frozenset({READS, WRITES}), type_rule=lambda ts, attrs: [],
    interp=lambda ctx, op: None, example="kd.fence", group="memory",
)  # fmt: skip
