"""Launch arguments in the memory layout the generated range functions read.

See ``lower`` for the layout: ``args[k]`` points at an array descriptor (data
pointer, shape, strides in scalar elements), a scalar or vector, or an array of
field pointers for a struct. The NumPy buffers built here must stay alive for
the whole launch; ``Packed`` holds them.
"""

from __future__ import annotations

import ctypes
from collections.abc import Sequence
from typing import Any

import numpy as np

from kdsl.errors import KdslLaunchError
from kdsl.ir import types as T


class Packed:
    """The ``args`` pointer array of one launch and everything it points into."""

    def __init__(
        self, types: Sequence[T.Type], values: Sequence[Any], extra: Sequence[int] = ()
    ) -> None:
        """Pack ``values``; ``extra`` raw pointers follow them (a debug build's error record)."""
        self.keep: list[Any] = []
        ptrs = [self._pack(t, v, i) for i, (t, v) in enumerate(zip(types, values))]
        ptrs += list(extra)
        self.array = (ctypes.c_void_p * max(1, len(ptrs)))(*ptrs)
        self.address = ctypes.addressof(self.array)

    def _hold(self, arr: np.ndarray) -> int:
        self.keep.append(arr)
        return arr.ctypes.data

    def _pack(self, t: T.Type, value: Any, index: int) -> int:
        if isinstance(t, T.ArrayType):
            return self._hold(descriptor(t, value, index))
        if isinstance(t, T.StructType):
            fields = [self._pack(ft, v, index) for (_, ft), v in zip(t.fields, value)]
            arr = (ctypes.c_void_p * max(1, len(fields)))(*fields)
            self.keep.append(arr)
            return ctypes.addressof(arr)
        if isinstance(t, T.HandleType):
            return self._hold(np.array([value], dtype=np.uint64))
        dtype = T.elem_type(t).np_dtype
        return self._hold(np.ascontiguousarray(np.asarray(value, dtype=dtype).reshape(-1)))


def descriptor(t: T.ArrayType, buf: np.ndarray, index: int = 0) -> np.ndarray:
    """The descriptor of a NumPy buffer: [data, shape..., strides in elements...]."""
    item = T.elem_type(t.dtype).np_dtype.itemsize
    nd = t.ndim
    inner = T.value_shape(t.dtype)
    want_inner, step = [], item
    for n in reversed(inner):
        want_inner.append(step)
        step *= n
    if tuple(buf.strides[nd:]) != tuple(reversed(want_inner)) and buf.size:
        raise KdslLaunchError(
            f"argument {index}: the cpu backend needs the {t.dtype} components of each "
            f"element to be contiguous (strides {buf.strides})"
        )
    strides = buf.strides[:nd]
    if any(s % item for s in strides):
        raise KdslLaunchError(
            f"argument {index}: strides {strides} are not multiples of the element "
            f"size {item}; the cpu backend cannot address this array"
        )
    out = np.empty(1 + 2 * nd, dtype=np.int64)
    out[0] = buf.__array_interface__["data"][0]
    out[1 : 1 + nd] = buf.shape[:nd]
    out[1 + nd :] = [s // item for s in strides]
    return out
