"""How the runtime maps user dtypes to IR types and NumPy buffers."""

from __future__ import annotations

import builtins
from typing import Any

import numpy as np

from kdsl.errors import KdslError
from kdsl.ir import bfloat16
from kdsl.ir import types as T
from kdsl.types import class_of, type_of


def resolve_dtype(dtype: Any) -> T.Type:
    """The IR element type of an array dtype (``float`` -> f32, ``vec3`` -> vec<3, f32>)."""
    try:
        t = type_of(dtype)
    except TypeError as e:
        raise KdslError(f"{dtype!r} is not an array dtype kdsl knows: {e}") from None
    if isinstance(t, T.StructType):
        try:
            T.storage_dtype(t)
        except TypeError:
            raise KdslError(
                f"arrays of {t} are not supported: a struct holding arrays or handles has no "
                "memory layout for an array element"
            ) from None
    elif not isinstance(t, T.ScalarType | T.VectorType | T.MatrixType):
        raise KdslError(
            f"arrays of {t} are not supported yet (use scalar, vector, matrix or struct dtypes)"
        )
    return t


def np_dtype(t: T.Type) -> np.dtype:
    """The NumPy dtype of one scalar component of ``t`` (a struct: its structured dtype)."""
    if isinstance(t, T.StructType):
        return T.storage_dtype(t)
    return T.elem_type(t).np_dtype


def inner_shape(t: T.Type) -> tuple[int, ...]:
    """The trailing NumPy dims one element of ``t`` takes (``(3,)`` for vec3, ``()`` for structs)."""
    return () if isinstance(t, T.StructType) else T.value_shape(t)


def public_dtype(t: T.Type) -> type:
    """The class users see as ``array.dtype`` (``kdsl.float32``, ``kdsl.vec3``, a struct...)."""
    if isinstance(t, T.StructType):
        from kdsl.runtime.structs import class_of_struct

        return class_of_struct(t)
    return class_of(t)


def host_value(t: T.Type, value: Any) -> Any:
    """A fill or element value as NumPy takes it: struct instances become tuples, and
    numbers for bfloat16 arrays their bits (uint16 data is taken as bits, as Warp does)."""
    if t is T.BF16:
        return bfloat16_bits_of(value)
    if isinstance(t, T.StructType) and hasattr(value, "numpy_value"):
        return value.numpy_value()
    if isinstance(t, T.StructType) and isinstance(value, list):  # a list of instances
        return [host_value(t, v) for v in value]
    return value


def dtype_of_value(value: Any) -> T.Type:
    """The dtype ``full`` infers from a fill value, as Warp does."""
    t = getattr(type(value), "__kdsl_type__", None)
    if isinstance(t, T.Type):
        return t
    if isinstance(value, builtins.bool | np.bool_):
        return T.BOOL
    if isinstance(value, builtins.int):
        return T.I32
    if isinstance(value, builtins.float):
        return T.F32
    if isinstance(value, np.generic):
        return T.scalar_from_numpy(value.dtype)
    arr = np.asarray(value)
    if arr.ndim in (1, 2) and arr.dtype.kind in "iuf":
        if isinstance(value, np.ndarray):
            et = T.scalar_from_numpy(arr.dtype)
        else:  # Python numbers: float -> f32, int -> i32, as for scalars
            et = T.F32 if arr.dtype.kind == "f" else T.I32
        if arr.ndim == 1:
            return T.VectorType(arr.shape[0], et)
        return T.MatrixType(arr.shape[0], arr.shape[1], et)
    raise KdslError(f"cannot infer an array dtype from the value {value!r}; pass dtype=")


def normalize_shape(shape: Any, what: str = "shape") -> tuple[int, ...]:
    """An int or a sequence of 1 to 4 non-negative ints, as a tuple."""
    if isinstance(shape, builtins.int | np.integer) and not isinstance(shape, builtins.bool):
        dims: tuple = (int(shape),)
    else:
        try:
            dims = tuple(shape)
        except TypeError:
            raise KdslError(f"{what} must be an int or a tuple of ints, got {shape!r}") from None
        for d in dims:
            if not isinstance(d, builtins.int | np.integer) or isinstance(d, builtins.bool):
                raise KdslError(f"{what} must be an int or a tuple of ints, got {shape!r}")
        dims = tuple(int(d) for d in dims)
    if not 1 <= len(dims) <= 4:
        raise KdslError(f"{what} must have 1 to 4 dimensions, got {len(dims)}: {shape!r}")
    if any(d < 0 for d in dims):
        raise KdslError(f"{what} must not be negative, got {shape!r}")
    return dims


def scalar_dtype_of_numpy(dtype: np.dtype) -> T.ScalarType:
    """The scalar type of NumPy data when no dtype is given."""
    try:
        return T.scalar_from_numpy(dtype)
    except KeyError:
        raise KdslError(f"NumPy dtype {dtype} has no kdsl equivalent") from None


def bfloat16_bits_of(value: Any) -> Any:
    """Data for a bfloat16 array as its bits: uint16 data and ``ml_dtypes`` bfloat16 data
    as they are, anything else rounded from float32 (``kdsl.ir.bfloat16.to_bits``)."""
    if isinstance(value, np.ndarray | np.generic):
        if value.dtype == np.uint16:
            return value
        if value.dtype == bfloat16.numpy_dtype():
            return value.view(np.uint16)
    if hasattr(value, "__cuda_array_interface__"):  # device data: left to the copy's checks
        return value
    return bfloat16.to_bits(value)


def host_view(t: T.Type, data: np.ndarray) -> np.ndarray:
    """Host data of an array of ``t`` as users see it: bfloat16 bits as ``ml_dtypes``'s
    bfloat16 when that package is installed (else the uint16 bits, as Warp does)."""
    if t is T.BF16:
        dt = bfloat16.numpy_dtype()
        return data.view(dt) if dt is not None else data
    return data


def host_scalar(t: T.Type, x: Any) -> Any:
    """One scalar element read from the host (a bfloat16's bits become its float32)."""
    if t is not T.BF16:
        return x
    x = np.asarray(x)
    return bfloat16.from_bits(x if x.dtype == np.uint16 else x.view(np.uint16))[()]
