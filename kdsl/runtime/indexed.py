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
from kdsl.runtime import cuda_memory as mem
from kdsl.runtime.alloc import zeros
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

    #: An indexed array is never contiguous (Warp's attribute).
    is_contiguous = False

    def _require_data(self, what: str) -> array:
        if self.data is None:
            raise KdslError(f"indexedarray.{what}(): this indexedarray is an annotation (no data)")
        return self.data

    def _key(self) -> tuple:
        # Per-dim index vectors on the data's device, combined as an outer product.
        data = self._require_data("index")
        xp = mem.xp(data.device)
        with mem.scope(data.device):
            vecs = [xp.arange(n, dtype=np.int64) if ix is None else ix._buf.astype(np.int64)
                    for n, ix in zip(data.shape, self.indices)]  # fmt: skip
            return xp.ix_(*vecs)

    def contiguous(self) -> array:
        """The viewed elements gathered into a new contiguous array on the data's device."""
        data = self._require_data("contiguous")
        if 0 in self.shape:
            return zeros(self.shape, dtype=data.dtype, device=data.device)
        with mem.scope(data.device):
            buf = data._buf[self._key()]
        return array._wrap(buf, data._t, data.device)

    def numpy(self) -> np.ndarray:
        """The viewed elements gathered into a new NumPy array."""
        return self.contiguous().numpy()

    def list(self) -> list:
        """The viewed elements as a flat Python list (as ``array.list``)."""
        return self.contiguous().list()

    def to(self, device: Any) -> array:
        """The viewed elements as a contiguous array on ``device`` (Warp's ``to``)."""
        return self.contiguous().to(device)

    def assign(self, src: Any) -> indexedarray:
        """Write ``src`` (an array, NumPy array or list of this shape) into the viewed elements."""
        data = self._require_data("assign")
        if isinstance(src, indexedarray):
            src = src.contiguous()
        value = src if isinstance(src, array) else array(src, dtype=data.dtype)
        value = value.to(data.device)
        if value.shape != self.shape:
            raise KdslError(
                f"indexedarray.assign(): a {value.shape} array does not fit shape {self.shape}"
            )
        with mem.scope(data.device):
            data._buf[self._key()] = value._buf
        return self

    def fill_(self, value: Any) -> indexedarray:
        """Set every viewed element to ``value`` (a scalar, or a vector for vector dtypes)."""
        data = self._require_data("fill_")
        if 0 in self.shape:
            return self
        part = self.contiguous().fill_(value)
        with mem.scope(data.device):
            data._buf[self._key()] = part._buf
        return self

    def zero_(self) -> indexedarray:
        """Set every viewed element to zero."""
        return self.fill_(0)

    def __len__(self) -> int:
        return self.shape[0]

    def __str__(self) -> str:
        return str(self.numpy()) if self.data is not None else repr(self)

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
