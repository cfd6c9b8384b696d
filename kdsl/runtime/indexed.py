"""``kdsl.indexedarray``: an array seen through index arrays, one per dimension (as Warp's).

``indexedarray(data, [idx0, None])`` views element ``(i, j)`` as
``data[idx0[i], j]``: a dimension with an index array has its length, one with
None keeps the data's. No IR type or op is added for it: its kernel type is a
struct (``kdsl.frontend.structs.indexed_type``) that the frontend lowers to loads of
the index arrays and the data, so every backend runs it unchanged.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from kdsl.errors import KdslError
from kdsl.frontend.structs import indexed_type
from kdsl.ir import types as T
from kdsl.runtime.annotation import ArrayAnnotation, subscript
from kdsl.runtime.array import array
from kdsl.runtime.dtypes import resolve_dtype


class indexedarray:
    """An array viewed through per-dimension index arrays; ``indexedarray(dtype=float)``
    with no data (or ``indexedarray[float]``) annotates a kernel parameter."""

    def __class_getitem__(cls, params: Any) -> ArrayAnnotation:
        """``indexedarray[dtype]`` or ``indexedarray[dtype, ndim]`` (Warp 1.19's syntax)."""
        return subscript(indexedarray, params, cls.__dict__.get("_fixed_ndim"))

    @staticmethod
    def annotation_type(dtype: Any, ndim: int) -> T.StructType:
        """The kernel type of an ``ndim``-d indexed array of ``dtype`` (for ``ArrayAnnotation``)."""
        return indexed_type(resolve_dtype(dtype), ndim)

    def __init__(
        self, data: array | None = None, indices: Any = None, dtype: Any = Any, ndim: int = 1
    ) -> None:
        if data is None:
            self.data, self.indices = None, [None] * ndim
            self._t = indexed_type(resolve_dtype(dtype if dtype is not Any else float), ndim)
            self.shape = (0,) * ndim
            return
        if not isinstance(data, array):
            raise KdslError(f"indexedarray() views a kdsl array, not {type(data).__name__}")
        nd = data.ndim
        idx = list(indices) if isinstance(indices, list | tuple) else [indices]
        idx += [None] * (nd - len(idx))
        if len(idx) != nd:
            raise KdslError(f"indexedarray(): {len(idx)} index arrays for a {nd}-d array")
        shape = []
        for k, ix in enumerate(idx):
            if ix is None:
                shape.append(data.shape[k])
                continue
            if not isinstance(ix, array) or ix._t != T.I32 or ix.ndim != 1:
                raise KdslError(f"indexedarray(): index {k} must be a 1-d int32 kdsl array")
            if ix.device != data.device:
                raise KdslError("indexedarray(): the indices must live on the data's device")
            shape.append(ix.shape[0])
        self.data, self.indices, self.shape = data, idx, tuple(shape)
        self._t = indexed_type(data._t, nd)

    @property
    def __kdsl_type__(self) -> T.StructType:
        return self._t

    @property
    def ndim(self) -> int:
        return len(self.indices)

    @property
    def dtype(self) -> Any:
        return self.data.dtype if self.data is not None else None

    @property
    def device(self) -> Any:
        return self.data.device if self.data is not None else None

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))

    def __getattr__(self, name: str) -> Any:
        # The struct fields a launch reads (idx<k>, shape<k>), by name.
        if name.startswith("idx") and name[3:].isdigit():
            return self.indices[int(name[3:])]
        if name.startswith("shape") and name[5:].isdigit():
            return self.shape[int(name[5:])]
        raise AttributeError(name)

    def numpy(self) -> np.ndarray:
        """The viewed elements gathered into a new NumPy array."""
        out = self.data.numpy()
        for k, ix in enumerate(self.indices):
            if ix is not None:
                out = np.take(out, ix.numpy(), axis=k)
        return out

    def __repr__(self) -> str:
        return f"indexedarray(shape={self.shape}, dtype={self._t.fields[0][1].dtype})"


def _annotation(ndim: int) -> type:
    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs["ndim"] = ndim
        indexedarray.__init__(self, *args, **kwargs)

    doc = f"A {ndim}-d ``indexedarray``."
    return type(f"indexedarray{ndim}d", (indexedarray,),
                {"__init__": __init__, "__doc__": doc, "_fixed_ndim": ndim})  # fmt: skip


indexedarray1d, indexedarray2d, indexedarray3d, indexedarray4d = (
    _annotation(n) for n in (1, 2, 3, 4)
)

__all__ = ["indexedarray", "indexedarray1d", "indexedarray2d", "indexedarray3d",
           "indexedarray4d"]  # fmt: skip
