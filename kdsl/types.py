"""Public kdsl types: ``float32``, ``vec3``, ``mat33``, ``quat``, ``transform``...

These are the names users write in annotations and in Python scope, as in Warp.
Each class carries ``__kdsl_type__``, its IR type (from ``kdsl.ir.types``, the one
dtype table). ``type_of(annotation)`` turns any annotation into an IR type.

In Python scope, ``kdsl.float32(1.5)`` gives a NumPy ``float32`` and
``kdsl.vec3(1, 2, 3)`` gives a ``vec3`` (a NumPy array subclass of shape (3,)).
"""

from __future__ import annotations

import builtins
from typing import Any

import numpy as np

from kdsl.ir import types as T

__all__ = [
    "Scalar", "Composite", "bool", "int8", "int16", "int32", "int64", "uint8", "uint16",
    "uint32", "uint64", "float16", "float32", "float64", "half", "vector", "matrix",
    "quaternion", "transformation", "vec2", "vec3", "vec4", "vec2f", "vec3f", "vec4f",
    "vec2d", "vec3d", "vec4d", "vec2h", "vec3h", "vec4h", "vec2i", "vec3i", "vec4i",
    "vec2ui", "vec3ui", "vec4ui", "vec2b", "vec3b", "vec4b", "vec2ub", "vec3ub", "vec4ub",
    "vec2s", "vec3s", "vec4s", "vec2us", "vec3us", "vec4us", "vec2l", "vec3l", "vec4l",
    "vec2ul", "vec3ul", "vec4ul", "mat22", "mat33", "mat44", "mat22f", "mat33f", "mat44f",
    "mat22d", "mat33d", "mat44d", "mat22h", "mat33h", "mat44h", "quat", "quatf", "quatd",
    "quath", "transform", "transformf", "transformd", "transformh", "spatial_vector",
    "spatial_vectorf", "spatial_vectord", "spatial_vectorh", "spatial_matrix", "spatial_matrixf",
    "spatial_matrixd", "spatial_matrixh", "type_of", "class_of",
    "dtype_to_numpy", "dtype_from_numpy",
]  # fmt: skip


class Scalar:
    """Base of the scalar type classes. Calling one converts a Python value."""

    __kdsl_type__: T.ScalarType

    def __new__(cls, value: Any = 0) -> Any:  # type: ignore[misc]
        return cls.__kdsl_type__.np_dtype.type(value)


def _scalar(t: T.ScalarType) -> type:
    name = t.np_dtype.name  # Warp names its scalars as NumPy does
    return type(name, (Scalar,), {"__kdsl_type__": t, "__doc__": f"The {t} scalar type."})


#: The public class of each scalar type, one per row of the IR's scalar table.
SCALAR_CLASSES: dict[T.ScalarType, type] = {t: _scalar(t) for t in T.SCALARS.values()}

# The public names, spelled out so that tools and readers see them.
bool = SCALAR_CLASSES[T.BOOL]  # noqa: A001 - Warp's name
int8 = SCALAR_CLASSES[T.I8]
int16 = SCALAR_CLASSES[T.I16]
int32 = SCALAR_CLASSES[T.I32]
int64 = SCALAR_CLASSES[T.I64]
uint8 = SCALAR_CLASSES[T.U8]
uint16 = SCALAR_CLASSES[T.U16]
uint32 = SCALAR_CLASSES[T.U32]
uint64 = SCALAR_CLASSES[T.U64]
float16 = SCALAR_CLASSES[T.F16]
float32 = SCALAR_CLASSES[T.F32]
float64 = SCALAR_CLASSES[T.F64]
half = float16


class Composite(np.ndarray):
    """Base of vector, matrix, quaternion and transform classes (Python scope values)."""

    __kdsl_type__: T.Type

    def __new__(cls, *args: Any) -> Composite:
        t = cls.__kdsl_type__
        shape = T.value_shape(t)
        dtype = T.elem_type(t).np_dtype
        size = int(np.prod(shape))
        if not args:
            flat = np.zeros(size, dtype)
        elif len(args) == 1 and np.ndim(args[0]) == 0:
            flat = np.full(size, args[0], dtype)
        else:
            flat = np.concatenate([np.ravel(np.asarray(a, dtype)) for a in args])
            if flat.size != size:
                raise ValueError(f"{cls.__name__} takes {size} components, got {flat.size}")
        return flat.reshape(shape).view(cls)


_COMPOSITE_CACHE: dict[T.Type, type] = {}


def _composite(t: T.Type, name: str) -> type:
    cls = _COMPOSITE_CACHE.get(t)
    if cls is None:
        cls = type(name, (Composite,), {"__kdsl_type__": t, "__doc__": f"The {t} type."})
        _COMPOSITE_CACHE[t] = cls
    return cls


def _scalar_type(dtype: Any) -> T.ScalarType:
    t = type_of(dtype)
    if not isinstance(t, T.ScalarType):
        raise TypeError(f"expected a scalar dtype, got {dtype!r}")
    return t


def vector(length: int, dtype: Any = float32) -> type:
    """The vector class of ``length`` components of ``dtype``."""
    et = _scalar_type(dtype)
    return _composite(T.VectorType(length, et), f"vec{length}{et.suffix}")


def matrix(shape: tuple[int, int], dtype: Any = float32) -> type:
    """The matrix class of ``shape`` (rows, cols) of ``dtype``."""
    et = _scalar_type(dtype)
    r, c = shape
    return _composite(T.MatrixType(r, c, et), f"mat{r}{c}{et.suffix}")


def quaternion(dtype: Any = float32) -> type:
    """The quaternion class of ``dtype``."""
    et = _scalar_type(dtype)
    return _composite(T.QuatType(et), f"quat{et.suffix}")


def transformation(dtype: Any = float32) -> type:
    """The rigid transform class of ``dtype``."""
    et = _scalar_type(dtype)
    return _composite(T.TransformType(et), f"transform{et.suffix}")


_PY_BUILTINS: dict[Any, T.Type] = {
    builtins.float: T.F32,
    builtins.int: T.I32,
    builtins.bool: T.BOOL,
}


def type_of(annotation: Any) -> T.Type:
    """The IR type an annotation or dtype names.

    Accepts Python's ``float`` (f32), ``int`` (i32) and ``bool``; kdsl type classes;
    NumPy scalar types and dtypes; IR types; and anything with ``__kdsl_type__``
    (array annotations, structs). Raises ``TypeError`` otherwise.
    """
    if isinstance(annotation, T.Type):
        return annotation
    if annotation in _PY_BUILTINS:
        return _PY_BUILTINS[annotation]
    t = getattr(annotation, "__kdsl_type__", None)
    if isinstance(t, T.Type):
        return t
    try:
        return T.scalar_from_numpy(annotation)
    except (KeyError, TypeError):
        pass
    raise TypeError(f"{annotation!r} is not a kdsl type")


def class_of(t: T.Type) -> type:
    """The public class of an IR value type (the inverse of ``type_of``)."""
    if isinstance(t, T.ScalarType):
        return SCALAR_CLASSES[t]
    if isinstance(t, T.QuatType):
        return quaternion(SCALAR_CLASSES[t.elem])
    if isinstance(t, T.TransformType):
        return transformation(SCALAR_CLASSES[t.elem])
    if isinstance(t, T.VectorType):
        return vector(t.length, SCALAR_CLASSES[t.elem])
    if isinstance(t, T.MatrixType):
        return matrix((t.rows, t.cols), SCALAR_CLASSES[t.elem])
    raise TypeError(f"{t} has no public value class")


def dtype_to_numpy(dtype: Any) -> np.dtype:
    """The NumPy dtype of a kdsl scalar type (vectors: of their elements)."""
    return T.elem_type(type_of(dtype)).np_dtype


def dtype_from_numpy(dtype: Any) -> type:
    """The kdsl scalar class of a NumPy dtype; a ``KdslTypeError`` for one kdsl lacks."""
    try:
        return SCALAR_CLASSES[T.scalar_from_numpy(dtype)]
    except (KeyError, TypeError):
        from kdsl.errors import KdslTypeError

        raise KdslTypeError(
            f"NumPy dtype {np.dtype(dtype).name if _is_dtype(dtype) else repr(dtype)} has no kdsl "
            "equivalent (kdsl has bool, int8..int64, uint8..uint64, float16, float32, float64)"
        ) from None


def _is_dtype(dtype: Any) -> bool:
    try:
        np.dtype(dtype)
    except TypeError:
        return False
    return True


vec2, vec3, vec4 = (vector(n) for n in (2, 3, 4))
vec2f, vec3f, vec4f = vec2, vec3, vec4
vec2d, vec3d, vec4d = (vector(n, float64) for n in (2, 3, 4))
vec2h, vec3h, vec4h = (vector(n, float16) for n in (2, 3, 4))
vec2i, vec3i, vec4i = (vector(n, int32) for n in (2, 3, 4))
vec2ui, vec3ui, vec4ui = (vector(n, uint32) for n in (2, 3, 4))
vec2b, vec3b, vec4b = (vector(n, int8) for n in (2, 3, 4))
vec2ub, vec3ub, vec4ub = (vector(n, uint8) for n in (2, 3, 4))
vec2s, vec3s, vec4s = (vector(n, int16) for n in (2, 3, 4))
vec2us, vec3us, vec4us = (vector(n, uint16) for n in (2, 3, 4))
vec2l, vec3l, vec4l = (vector(n, int64) for n in (2, 3, 4))
vec2ul, vec3ul, vec4ul = (vector(n, uint64) for n in (2, 3, 4))
mat22, mat33, mat44 = (matrix((n, n)) for n in (2, 3, 4))
mat22f, mat33f, mat44f = mat22, mat33, mat44
mat22d, mat33d, mat44d = (matrix((n, n), float64) for n in (2, 3, 4))
mat22h, mat33h, mat44h = (matrix((n, n), float16) for n in (2, 3, 4))
quat = quatf = quaternion()
quatd, quath = quaternion(float64), quaternion(float16)
transform = transformf = transformation()
transformd, transformh = transformation(float64), transformation(float16)
# Spatial (6D) vectors and matrices, as in Warp: (angular, linear) halves.
spatial_vector = spatial_vectorf = vector(6)
spatial_vectord, spatial_vectorh = vector(6, float64), vector(6, float16)
spatial_matrix = spatial_matrixf = matrix((6, 6))
spatial_matrixd, spatial_matrixh = matrix((6, 6), float64), matrix((6, 6), float16)
