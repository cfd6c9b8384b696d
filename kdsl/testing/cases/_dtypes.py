"""Dtype tables shared by the atomics and integer-semantics conformance cases."""

from __future__ import annotations

from typing import Any

import numpy as np

import kdsl as wp

#: (name, kdsl dtype, NumPy dtype, required capabilities)
INT_TYPES = (
    ("i32", wp.int32, np.int32, ()),
    ("u32", wp.uint32, np.uint32, ()),
    ("i64", wp.int64, np.int64, ("int64",)),
    ("u64", wp.uint64, np.uint64, ("int64",)),
)
FLOAT_TYPES = (
    ("f32", wp.float32, np.float32, ()),
    ("f64", wp.float64, np.float64, ("fp64",)),
)
SMALL_INT_TYPES = (
    ("i8", wp.int8, np.int8, ("int8",)),
    ("u8", wp.uint8, np.uint8, ("int8",)),
    ("i16", wp.int16, np.int16, ("int16",)),
    ("u16", wp.uint16, np.uint16, ("int16",)),
)


def wrap(values: Any, np_dtype: Any) -> np.ndarray:
    """Python integers reduced into ``np_dtype``'s range (two's complement)."""
    info = np.iinfo(np_dtype)
    span = 1 << info.bits
    return np.array([(int(v) - int(info.min)) % span + int(info.min) for v in values], np_dtype)
