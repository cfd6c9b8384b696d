"""Argument checks and conversions of ``kdsl.Volume``'s constructors, with Warp's rules:
which grid type a background value makes, voxel sizes and transforms, and how tile or
voxel points (index or world space) become index coordinates.
"""

from __future__ import annotations

import math
import numbers
from typing import Any

import numpy as np

from kdsl.errors import KdslError, KdslTypeError
from kdsl.geometry.nanovdb.layout import GridType
from kdsl.ir import types as T
from kdsl.runtime.array import array
from kdsl.types import type_of


class VolumeError(KdslError, ValueError, RuntimeError):
    """A bad ``Volume`` argument value (a ``ValueError`` and a ``RuntimeError`` too, the
    classes Warp raises for these)."""


# IR value type of a background value -> the grid type it makes (Warp's allocation types)
_GRID_TYPES = {
    T.F32: GridType.FLOAT, T.F64: GridType.DOUBLE, T.I32: GridType.INT32,
    T.U32: GridType.UINT32, T.I64: GridType.INT64,
    T.VectorType(3, T.F32): GridType.VEC3F, T.VectorType(3, T.F64): GridType.VEC3D,
    T.VectorType(4, T.F32): GridType.VEC4F, T.VectorType(4, T.F64): GridType.VEC4D,
}  # fmt: skip


def grid_type_of_background(bg_value: Any) -> GridType:
    """The grid type ``bg_value`` makes (``None``: an OnIndex grid): Python ``int`` makes
    int32, ``float`` float32, NumPy scalars and kdsl vectors their own type, and a plain
    sequence of 3 or 4 numbers vec3f or vec4f."""
    if bg_value is None:
        return GridType.ONINDEX
    if isinstance(bg_value, bool | np.bool_):
        raise KdslTypeError("Volume bg_value cannot be a bool: bool grids are not supported")
    t = getattr(type(bg_value), "__kdsl_type__", None)
    if t is None and isinstance(bg_value, numbers.Number | np.generic):
        try:
            t = type_of(type(bg_value))
        except TypeError:
            t = None
    if t is None and isinstance(bg_value, list | tuple | np.ndarray) and len(bg_value) in (3, 4):
        t = T.VectorType(len(bg_value), T.F32)
    if t not in _GRID_TYPES:
        raise KdslTypeError(
            f"Volume bg_value {bg_value!r} makes no supported grid type: use an int, a float, "
            "an int32/uint32/int64/float32/float64 scalar, a vec3/vec4 (f or d), or None for "
            "an index grid"
        )
    return _GRID_TYPES[t]


def voxel_sizes(voxel_size: Any) -> tuple[float, float, float]:
    """A scalar or 3-sequence voxel size as three positive finite floats."""
    if isinstance(voxel_size, numbers.Real) and not isinstance(voxel_size, bool):
        sizes = (float(voxel_size),) * 3
    elif isinstance(voxel_size, list | tuple | np.ndarray):
        sizes = tuple(float(v) for v in np.asarray(voxel_size, dtype=np.float64).ravel())
        if len(sizes) != 3:
            raise VolumeError(f"Volume voxel_size must be a scalar or 3 values, not {voxel_size!r}")
    else:
        raise KdslTypeError(f"Volume voxel_size must be a number or 3 numbers, not {voxel_size!r}")
    if not all(math.isfinite(v) and v > 0 for v in sizes):
        raise VolumeError(f"Volume voxel_size must be positive and finite, not {voxel_size!r}")
    return sizes  # type: ignore[return-value]


def vector3(value: Any, name: str) -> np.ndarray:
    """Three finite float64 values."""
    try:
        v = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        v = None
    if v is None or v.shape != (3,):
        raise KdslTypeError(f"Volume {name} must be 3 numbers, not {value!r}")
    if np.isfinite(v).all():
        return v
    raise VolumeError(f"Volume {name} must be finite, not {value!r}")


def index_to_world(voxel_size: Any, transform: Any) -> np.ndarray:
    """The 3x3 linear part: ``diag(voxel_size)``, or ``transform`` (exactly one given)."""
    if transform is None:
        if voxel_size is None:
            raise VolumeError("Volume needs a voxel_size or a transform")
        return np.diag(voxel_sizes(voxel_size))
    if voxel_size is not None:
        raise VolumeError("Volume takes a voxel_size or a transform, not both")
    mat = np.asarray(transform, dtype=np.float64)
    if mat.size != 9 or not np.isfinite(mat).all():
        raise VolumeError(f"Volume transform must be a finite 3x3 matrix, not {transform!r}")
    mat = mat.reshape(3, 3)
    if abs(np.linalg.det(mat)) < 1e-30:
        raise VolumeError(f"Volume transform {mat.tolist()} is singular")
    return mat


def points_to_coords(points: Any, mat: np.ndarray, translation: np.ndarray, name: str):
    """Index coordinates (N, 3) int64 of a kdsl array of points: int32 points are index
    coordinates; float32 points are world positions, mapped by the inverse transform in
    float32 and rounded half up, as NanoVDB's ``applyInverseMapF(p).round()``."""
    if not isinstance(points, array):
        raise KdslTypeError(f"Volume {name} must be a kdsl.array, not {type(points).__name__}")
    t = type_of(points.dtype)
    scalar = T.elem_type(t) if isinstance(t, T.VectorType) else t
    shape_ok = (isinstance(t, T.VectorType) and t.length == 3 and points.ndim == 1) or (
        isinstance(t, T.ScalarType) and points.ndim == 2 and points.shape[1] == 3
    )
    if not shape_ok or scalar not in (T.I32, T.F32):
        raise KdslTypeError(
            f"Volume {name} must be a 1-d vec3i/vec3f array or an (N, 3) int32/float32 array, "
            f"not {points.ndim}-d {t}"
        )
    host = np.asarray(points.numpy()).reshape(-1, 3)
    if scalar == T.I32:
        return host.astype(np.int64)
    inv = np.linalg.inv(mat).astype(np.float32)
    index = (host.astype(np.float32) - translation.astype(np.float32)) @ inv.T
    if not np.isfinite(index).all() or np.abs(index).max(initial=0) >= 2**31 - 1:
        raise VolumeError(f"Volume {name} hold positions outside the int32 index space")
    return np.floor(index + np.float32(0.5)).astype(np.int64)
