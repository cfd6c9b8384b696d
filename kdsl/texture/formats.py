"""Texel formats, texture data shapes and mip chains of ``kdsl.Texture`` (Warp 1.19's rules).

- ``texel_format(dtype)``: a supported texel type's NumPy dtype and Warp's format code;
- ``parse_data(data, ndim)``: NumPy or kdsl-array texture data as a host array of shape
  ``(depth, height, width, channels)`` (1 where the texture has no such axis), its
  format and its channel count;
- ``mip_shapes`` and ``mip_chain``: the ``(width, height, depth)`` of each level, and
  the levels' data made by a 2x box filter (pairs of texels averaged in float64,
  integers rounded to nearest and clipped back into their type).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from kdsl.errors import KdslValueError
from kdsl.ir import types as T
from kdsl.runtime.array import array
from kdsl.stdlib import texture as S
from kdsl.types import type_of

#: Warp's cap on mip levels.
MAX_MIP_LEVELS = 16
#: Texel elements (all levels, all channels) a kernel indexes with int32.
MAX_ELEMENTS = 2**31 - 1

#: Supported texel types: NumPy dtype -> Warp's format code.
FORMATS: dict[np.dtype, int] = {
    np.dtype(np.uint8): S.UINT8, np.dtype(np.uint16): S.UINT16,
    np.dtype(np.float32): S.FLOAT32, np.dtype(np.int8): S.INT8,
    np.dtype(np.int16): S.INT16, np.dtype(np.float16): S.FLOAT16,
    np.dtype(np.uint32): S.UINT32, np.dtype(np.int32): S.INT32,
}  # fmt: skip
#: The formats sampled as plain numbers, which only ``CLOSEST`` filtering supports.
INTEGER32 = (S.UINT32, S.INT32)
_NAMES = ", ".join(sorted(d.name for d in FORMATS))  # for messages


class TextureError(KdslValueError):
    """A bad ``kdsl.Texture`` argument (a ``ValueError``, as Warp raises)."""


def texel_format(dtype: Any) -> np.dtype:
    """The NumPy dtype of texel type ``dtype`` (``float`` is float32, ``int`` int32)."""
    try:
        t = type_of(dtype)
    except TypeError:
        t = None
    np_dtype = t.np_dtype if isinstance(t, T.ScalarType) and not t.is_bool else None
    if np_dtype not in FORMATS:
        name = str(dtype) if isinstance(dtype, np.dtype) else getattr(dtype, "__name__", dtype)
        raise TextureError(f"unsupported texture dtype {name}; supported: {_NAMES}")
    return np_dtype


def _host(data: Any) -> tuple[np.ndarray, int | None]:
    """``data`` on the host, and its channel count when its dtype is a vector."""
    if isinstance(data, array):
        t = type_of(data.dtype)
        channels = t.length if isinstance(t, T.VectorType) else None
        if not isinstance(t, T.VectorType | T.ScalarType):
            raise TextureError(f"texture data must hold scalars or vectors, not {t}")
        return np.ascontiguousarray(data.numpy()), channels
    if isinstance(data, np.ndarray):
        return np.ascontiguousarray(data), None
    raise TextureError(f"texture data must be a NumPy array or a kdsl.array, not "
                       f"{type(data).__name__}")  # fmt: skip


def parse_data(data: Any, ndim: int) -> tuple[np.ndarray, int]:
    """``(texels, channels)``: ``data`` as a ``(depth, height, width, channels)`` host
    array of a supported texel type, with Warp's shapes: ``(width[, channels])`` for 1-d,
    ``(height, width[, channels])`` for 2-d, ``(depth, height, width[, channels])`` for
    3-d, or the same without the channel axis for an array of vectors."""
    host, vec_channels = _host(data)
    texel_format(host.dtype)
    spatial = host.ndim - (1 if vec_channels is not None else 0)
    if vec_channels is None and host.ndim == ndim + 1:
        spatial = ndim
    if spatial != ndim or host.ndim > ndim + 1:
        what = "an array of vectors" if vec_channels is not None else "an array"
        raise TextureError(f"{ndim}-d texture data must be {what} with {ndim} dims"
                           + ("" if vec_channels else f" (or {ndim + 1}, the last channels)")
                           + f", got shape {host.shape}")  # fmt: skip
    if host.ndim == ndim:
        host = host[..., None]
    shape = (1,) * (3 - ndim) + host.shape
    return host.reshape(shape), int(shape[-1])


def mip_shapes(size: tuple[int, int, int], ndim: int, levels: int) -> list[tuple[int, int, int]]:
    """The ``(width, height, depth)`` of each mip level; ``levels == 0`` is the full chain
    down to one texel."""
    if levels < 0:
        raise TextureError(f"num_mip_levels must be >= 0, got {levels}")
    full = math.floor(math.log2(max(size[:ndim]))) + 1
    levels = levels or full
    if levels > full:
        raise TextureError(f"num_mip_levels ({levels}) exceeds the maximum for base "
                           f"dimensions {size[:ndim]} ({full})")  # fmt: skip
    if levels > MAX_MIP_LEVELS:
        raise TextureError(f"num_mip_levels ({levels}) exceeds the maximum supported mip "
                           f"levels ({MAX_MIP_LEVELS})")  # fmt: skip
    return [tuple(max(1, s >> m) for s in size) for m in range(levels)]  # type: ignore[misc]


def _halve(level: np.ndarray, axis: int, size: int) -> np.ndarray:
    """``level`` with pairs of texels along ``axis`` averaged down to ``size``."""
    if level.shape[axis] == size:
        return level
    pairs = np.take(level, np.arange(2 * size), axis=axis)
    shape = pairs.shape[:axis] + (size, 2) + pairs.shape[axis + 1:]
    return pairs.reshape(shape).mean(axis=axis + 1)


def mip_chain(base: np.ndarray, shapes: list[tuple[int, int, int]]) -> list[np.ndarray]:
    """The data of every mip level of ``shapes``, from ``base`` (a ``(d, h, w, c)`` array)."""
    levels = [base]
    wide = base.astype(np.float64)
    for w, h, d in shapes[1:]:
        for axis, size in ((2, w), (1, h), (0, d)):
            wide = _halve(wide, axis, size)
        if np.issubdtype(base.dtype, np.integer):
            info = np.iinfo(base.dtype)
            levels.append(np.clip(np.rint(wide), info.min, info.max).astype(base.dtype))
        else:
            levels.append(wide.astype(base.dtype))
        wide = levels[-1].astype(np.float64)
    return levels
