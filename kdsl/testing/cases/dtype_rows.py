"""Dtype tables shared by the atomics and integer-semantics conformance cases."""

from __future__ import annotations

from typing import Any

import numpy as np

from kdsl.ir import types as T
from kdsl.types import class_of


def dtype_row(t: T.ScalarType, requires: tuple[str, ...] = ()) -> tuple[str, type, type, tuple]:
    """(IR name, kdsl dtype, NumPy scalar type, required capabilities) of ``t``."""
    return t.name, class_of(t), t.np_dtype.type, requires


INT_TYPES = (
    dtype_row(T.I32),
    dtype_row(T.U32),
    dtype_row(T.I64, ("int64",)),
    dtype_row(T.U64, ("int64",)),
)
FLOAT_TYPES = (dtype_row(T.F32), dtype_row(T.F64, ("fp64",)))
SMALL_INT_TYPES = (
    dtype_row(T.I8, ("int8",)),
    dtype_row(T.U8, ("int8",)),
    dtype_row(T.I16, ("int16",)),
    dtype_row(T.U16, ("int16",)),
)


def wrap(values: Any, np_dtype: Any) -> np.ndarray:
    """Python integers reduced into ``np_dtype``'s range (two's complement)."""
    info = np.iinfo(np_dtype)
    span = 1 << info.bits
    return np.array([(int(v) - int(info.min)) % span + int(info.min) for v in values], np_dtype)
