"""Object records: how a runtime object (a BVH, a mesh...) is reached from a kernel.

A geometry object lives on one device as plain arrays (nodes, points, indices). Its
*record* is one struct value in that device's memory that holds the objects's
arrays (as descriptors) and scalars; the object's ``uint64`` id, the value kernels
receive (``mesh.id``), is the record's address. ``kd.record %id : struct<S>`` reads
the record at ``id`` as a value of struct type ``S``; from there the fields are
ordinary struct fields and the arrays ordinary arrays, so the queries written in
the standard library compile for every backend.

The layout is NumPy's and C's natural struct layout (``record_dtype``, the same rule
as ``types.storage_dtype``), where an array field is ``1 + 2 * ndim`` 64-bit words:
the data address, the shape and the strides **in bytes**. A record's first field is
a 64-bit *tag*, ``record_tag(name)`` of the struct's name, which the runtime zeroes
when the object is freed: a debug build checks it (``kd.check_record``) before the read.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
from collections.abc import Sequence
from typing import Any

import numpy as np

from kdsl.errors import KdslRuntimeError
from kdsl.ir.catalog import CATALOG, PURE
from kdsl.ir.core import Operation
from kdsl.ir.types import (
    U64,
    ArrayType,
    HandleType,
    StructType,
    Type,
    elem_type,
    storage_dtype,
    struct_dtype,
    value_shape,
)


def descriptor_words(ndim: int) -> int:
    """Number of 64-bit words of an ``ndim``-d array field in a record."""
    return 1 + 2 * ndim


@functools.cache
def record_dtype(t: Type) -> np.dtype:
    """The NumPy dtype of a record of struct type ``t`` (C's natural layout).

    As ``storage_dtype``, plus array fields (their descriptor words, int64) and
    handles (uint64), which only records may hold.
    """
    if isinstance(t, ArrayType):
        return np.dtype((np.int64, (descriptor_words(t.ndim),)))
    if isinstance(t, HandleType):
        return np.dtype(np.uint64)
    if not isinstance(t, StructType):
        return storage_dtype(t)
    return struct_dtype(t, record_dtype)


def field_offsets(t: StructType) -> list[int]:
    """The byte offset of each field of a record of ``t``, in field order."""
    dt = record_dtype(t)
    return [dt.fields[name][1] for name, _ in t.fields]


def record_tag(record: str) -> int:
    """The 64-bit tag a live record of the struct named ``record`` starts with (never 0)."""
    digest = hashlib.blake2b(f"kdsl-record:{record}".encode(), digest_size=8).digest()
    return int.from_bytes(digest, "little") | 1


def check_record_type(t: Type) -> StructType:
    """``t`` if it can be a record type (a struct whose first field is a uint64 tag)."""
    if not isinstance(t, StructType) or not t.fields or t.fields[0][1] != U64:
        raise TypeError(f"a record is a struct whose first field is a uint64 tag, not {t}")
    return t


def element_strides(t: ArrayType) -> tuple[int, int]:
    """(unit, count): strides of ``t`` in a record are bytes; the element's own scalar
    size ``unit`` (1 for structs) and its number of scalar components ``count``."""
    if isinstance(t.dtype, StructType):
        return 1, 1
    et = elem_type(t.dtype)
    n = 1
    for d in value_shape(t.dtype):
        n *= d
    return et.np_dtype.itemsize, n


# -- the interpreter's reading of a record --------------------------------------------


def array_from_words(t: ArrayType, words: Sequence[int]) -> np.ndarray:
    """The NumPy view of the memory an array descriptor (record words: the data address,
    the shape, the strides in bytes) describes; zeros for a null or empty one."""
    nd = t.ndim
    data, shape, strides = int(words[0]), tuple(words[1 : 1 + nd]), tuple(words[1 + nd :])
    inner = value_shape(t.dtype) if not isinstance(t.dtype, StructType) else ()
    dt = storage_dtype(t.dtype) if isinstance(t.dtype, StructType) else elem_type(t.dtype).np_dtype
    inner_strides, step = [], dt.itemsize
    for d in reversed(inner):
        inner_strides.append(step)
        step *= d
    full_shape = (*shape, *inner)
    full_strides = (*strides, *reversed(inner_strides))
    if any(s == 0 for s in shape) or data == 0:
        return np.zeros(full_shape, dtype=dt)
    span = sum((n - 1) * abs(s) for n, s in zip(full_shape, full_strides)) + dt.itemsize
    buf = (ctypes.c_char * span).from_address(data)
    return np.ndarray(full_shape, dtype=dt, buffer=buf, strides=full_strides)


def _value_from_bytes(t: Type, raw: bytes, offset: int) -> Any:
    if isinstance(t, StructType):
        return tuple(
            _value_from_bytes(ft, raw, offset + o) for (_, ft), o in zip(t.fields, field_offsets(t))
        )
    if isinstance(t, ArrayType):
        words = np.frombuffer(raw, np.int64, descriptor_words(t.ndim), offset)
        return array_from_words(t, words.tolist())
    if isinstance(t, HandleType):
        return np.frombuffer(raw, np.uint64, 1, offset)[0]
    dt = storage_dtype(t)
    v = np.frombuffer(raw, dt, 1, offset)[0]
    return v.copy() if isinstance(v, np.ndarray) else v


@functools.lru_cache(maxsize=256)
def _decode(t: StructType, raw: bytes) -> tuple:
    return _value_from_bytes(t, raw, 0)


def read_record(address: int, t: StructType) -> tuple:
    """The interpreter's value of the record of type ``t`` at ``address`` (host memory)."""
    if address == 0:
        raise KdslRuntimeError(f"an object id of 0 was read as a {t.name} (a null id)")
    raw = ctypes.string_at(address, record_dtype(t).itemsize)
    return _decode(t, raw)


def _record_interp(ctx, op: Operation, rid: Any) -> tuple:
    return read_record(int(rid), op.results[0].type)


def _verify_record(op: Operation) -> None:
    if len(op.operands) != 1 or op.operands[0].type != U64:
        raise TypeError("kd.record takes one uint64 id")
    if len(op.results) != 1:
        raise TypeError("kd.record gives one struct value")
    check_record_type(op.results[0].type)


RECORD = CATALOG.define(
    "kd.record",
    "The record of a runtime object (mesh, BVH...): the struct value stored at address "
    "``id`` of the running device, in ``record_dtype``'s layout (arrays as descriptors "
    "with byte strides). The id must be a live object's: a debug build checks its tag "
    "first (``kd.check_record``). Records do not change while a kernel runs.",
    traits=frozenset({PURE}), verifier=_verify_record, interp=_record_interp,
    folder=lambda op, values: None,  # never read memory at compile time
    example="%1 = kd.record %0 : struct<BvhRecord>", group="memory",
)  # fmt: skip
