"""``carve``: typed views of parts of one allocation, made in one call.

A geometry build allocates one block and views it as a dozen arrays of different
types (a BVH's nodes, its keys, its int32 arrays). ``kdsl.array(ptr=...)`` per view
converts and checks its dtype, shape and device each time and, on a GPU, wraps the
address in new unowned memory (tens of microseconds a view); slicing a view of the
right type costs a few. ``carve`` makes each view straight from the block's buffer
(CuPy's memory pointer plus an offset, or NumPy's buffer and an offset): the views
hold the block's memory alive, as a slice would.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from kdsl.errors import KdslError
from kdsl.runtime.array import array
from kdsl.runtime.dtypes import inner_shape, np_dtype, resolve_dtype

#: One view: (byte offset into the block, dtype, shape) or (..., byte strides of the
#: shape's dims); without strides the view is C-contiguous.
Part = tuple


def carve(block: array, parts: Sequence[Part]) -> list[array]:
    """Views of the C-contiguous array ``block``'s memory, one per part (see ``Part``):
    an array of the part's dtype and shape starting its offset bytes into the block.
    A part reaching outside the block, or at an offset its dtype's components cannot
    be read at (a multiple of their size), raises ``KdslError``."""
    buf = block._buf
    if not buf.flags.c_contiguous:
        raise KdslError("carve(): the block must be a C-contiguous array")
    nbytes, device = int(buf.nbytes), block.device
    on_gpu = device.is_cuda
    base = buf.data if on_gpu else buf.reshape(-1).view(np.uint8)
    ndarray = type(buf)  # numpy.ndarray or cupy.ndarray
    views = []
    for part in parts:
        offset, shape = part[0], part[2]
        t, dt, inner, item, inner_strides = _element(part[1])
        dims = (shape,) if type(shape) is int else tuple(shape)
        if len(part) > 3:
            outer = tuple(part[3])
        elif len(dims) == 1:
            outer = (item,)
        else:
            outer = tuple(item * math.prod(dims[k + 1 :]) for k in range(len(dims)))
        extent = 0 if 0 in dims else item + sum((d - 1) * s for d, s in zip(dims, outer))
        if extent == 0:  # an empty view reads nothing: anywhere will do
            offset = 0
        align = dt.alignment
        if offset < 0 or offset + extent > nbytes or min(outer) < 0:
            raise KdslError(f"carve(): {dims} of {t} at byte {offset} (strides {outer}) "
                            f"reaches outside the block's {nbytes} bytes")  # fmt: skip
        if offset % align or any(s % align for s in outer):
            raise KdslError(f"carve(): {t} at byte {offset} (strides {outer}) is not aligned "
                            f"to its {align}-byte components")  # fmt: skip
        full, strides = dims + inner, outer + inner_strides
        if on_gpu:
            view = ndarray(full, dt, memptr=base + offset, strides=strides)
        else:
            view = ndarray(full, dt, buffer=base, offset=offset, strides=strides)
        out = array._wrap(view, t, device)
        out._viewed = block
        views.append(out)
    return views


#: Per dtype object: (kernel type, NumPy dtype of a component, inner shape, element
#: bytes, the inner dims' strides).
_ELEMENTS: dict[Any, tuple] = {}


def _element(dtype: Any) -> tuple:
    hit = _ELEMENTS.get(dtype)
    if hit is None:
        t = resolve_dtype(dtype)
        dt, inner = np_dtype(t), inner_shape(t)
        inner_strides = tuple(dt.itemsize * math.prod(inner[k + 1 :]) for k in range(len(inner)))
        hit = _ELEMENTS[dtype] = (t, dt, inner, dt.itemsize * math.prod(inner), inner_strides)
    return hit
