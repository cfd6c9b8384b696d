"""``kdsl.fixedarray``: the type of a thread-local array made by ``zeros`` in a kernel.

As in Warp 1.19 it is a compile-time type, never a host array: ``fixedarray(dtype,
shape)`` describes an array of constant ``shape``, and as an annotation of a
``@kdsl.func`` parameter or result it means an array of that dtype and rank (in kdsl a
local array is an ordinary array value, see ``kd.local_array``; the shape is not part
of the kernel type). Kernel parameters come from the host, so they cannot be local
arrays: annotate them with ``array``.
"""

from __future__ import annotations

import math
from typing import Any

from kdsl.errors import KdslError
from kdsl.ir import types as T
from kdsl.ir.ops_local import dense_strides, local_array_error
from kdsl.runtime.dtypes import public_dtype, resolve_dtype


class fixedarray:
    """A fixed-size, thread-local array type (see the module docstring)."""

    def __init__(self, dtype: Any = float, shape: int | tuple[int, ...] = (1,)) -> None:
        dims = (shape,) if isinstance(shape, int) else tuple(shape)
        t = resolve_dtype(dtype)
        why = local_array_error(t, dims)
        if why is not None:
            raise KdslError(f"fixedarray(): {why}")
        self._t = t
        self.dtype = public_dtype(t)
        self.shape = dims
        self.ndim = len(dims)
        self.size = math.prod(dims)
        #: Row-major strides in bytes, as Warp's.
        self.strides = tuple(dense_strides(T.ArrayType(t, self.ndim), dims, 1))

    @property
    def __kdsl_type__(self) -> T.ArrayType:
        return T.ArrayType(self._t, self.ndim)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, fixedarray):
            return NotImplemented
        return (self._t, self.shape) == (other._t, other.shape)

    def __hash__(self) -> int:
        return hash((self._t, self.shape))

    def __repr__(self) -> str:
        name = getattr(self.dtype, "__name__", str(self.dtype))
        return f"fixedarray(dtype={name}, shape={self.shape})"
