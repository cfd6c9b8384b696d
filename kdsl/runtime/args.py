"""Launch argument checking and conversion.

Each argument is checked against its parameter's IR type and turned into what
backends take: arrays as their buffers with element dims appended (NumPy on the
CPU, ``cupy.ndarray`` on a CUDA device, where any ``__cuda_array_interface__``
object on that device is also taken zero-copy; DLPack producers and
``__array_interface__`` objects such as PyTorch CPU tensors and JAX arrays are
read zero-copy too, through the interop layer's ``foreign_buffer``), scalars as
NumPy scalars of the exact type, vectors/matrices as NumPy arrays, structs as
tuples. Python numbers get Warp's leniency (an int for a float parameter is
fine); NumPy data must match exactly, so a float64 array or scalar is never
narrowed to float32 silently.
"""

from __future__ import annotations

import builtins
import sys
from typing import Any

import numpy as np

from kdsl.errors import KdslLaunchError
from kdsl.ir import types as T
from kdsl.runtime import cuda_memory as mem
from kdsl.runtime.adapters import adapter
from kdsl.runtime.array import array
from kdsl.runtime.descriptor import ArrayDescriptor
from kdsl.runtime.device import Device


class ArgError(Exception):
    """A mismatch found by ``convert``; the launcher adds kernel and parameter names."""


def describe(value: Any) -> str:
    """A short description of a launch argument for error messages."""
    if isinstance(value, array):
        return f"array of {value._t} with {value.ndim} dims on '{value.device}'"
    if mem.is_cuda_buffer(value):
        face = value.__cuda_array_interface__
        return (
            f"CUDA {type(value).__name__} of {np.dtype(face['typestr'])} and shape "
            f"{tuple(face['shape'])}"
        )
    if isinstance(value, np.ndarray):
        return f"NumPy {value.dtype} array of shape {value.shape}"
    t = getattr(type(value), "__kdsl_type__", None)
    if isinstance(t, T.Type):
        return str(t)
    if isinstance(value, np.generic):
        return f"NumPy {value.dtype}"
    return f"{type(value).__name__} {value!r}" if np.ndim(value) == 0 else type(value).__name__


def convert(t: T.Type, value: Any, device: Device) -> Any:
    """``value`` as the backend value of IR type ``t``; raises ``ArgError``."""
    # A JAX tracer exists only once JAX is loaded; never import it here.
    if "jax" in sys.modules:
        message = adapter("tracer_message")
        why = message(value) if message is not None else None
        if why is not None:
            raise ArgError(why)
    if isinstance(t, T.ArrayType):
        return _array(t, value, device)
    if isinstance(t, T.ScalarType):
        return convert_scalar(t, value)
    if isinstance(t, T.VectorType | T.MatrixType):
        return convert_composite(t, value)
    if isinstance(t, T.StructType):
        return _struct(t, value, device)
    if isinstance(t, T.HandleType):
        if isinstance(value, builtins.int | np.integer) and not isinstance(value, builtins.bool):
            return np.uint64(value)
        raise ArgError(f"expected a {t} (an integer id), got {describe(value)}")
    raise ArgError(f"parameters of type {t} are not supported by launch")


def _array(t: T.ArrayType, value: Any, device: Device) -> Any:
    if type(value) is ArrayDescriptor:
        _check_kdsl_array(t, device, value.device, value.dtype, value.ndim)
        return value.buf
    if isinstance(value, array):
        _check_kdsl_array(t, device, value.device, value._t, value.ndim)
        return value._buf
    cached = adapter("cached_buffer")
    buf = None if cached is None else cached(t, value, device)
    if buf is not None:
        return buf
    if mem.is_cuda_buffer(value):
        if device.is_cpu:
            raise ArgError(
                f"expected an array on device 'cpu', got a CUDA {type(value).__name__} "
                f"(device memory)"
            )
        buf, where = mem.wrap_cuda(value)
        if where != device:
            raise ArgError(
                f"expected an array on device '{device}', got a CUDA {type(value).__name__} "
                f"on '{where}'"
            )
        check_foreign(t, buf.dtype, buf.shape, f"CUDA {type(value).__name__}")
        return buf
    if isinstance(value, np.ndarray):
        if not device.is_cpu:
            raise ArgError(
                f"a NumPy array lives on the cpu, but the launch is on '{device}'; "
                f"move it with kdsl.array(data, device='{device}')"
            )
        check_foreign(t, value.dtype, value.shape, "NumPy")
        return value
    if has_attribute(value, "__dlpack__") or has_attribute(value, "__array_interface__"):
        read = adapter("foreign_buffer")
        if read is not None:
            return read(t, value, device)
    raise ArgError(f"expected an array of {t.dtype}, got {describe(value)}")


def has_attribute(value: Any, name: str) -> bool:
    """``hasattr``, where a property that raises counts as a "no"."""
    try:
        return hasattr(value, name)
    except Exception:  # a property that raises (a CUDA object's __array_interface__) is a "no"
        return False


def _check_kdsl_array(t: T.ArrayType, device: Device, on: Device, dtype: Any, ndim: int) -> None:
    """Raise unless a kdsl array (or descriptor) on ``on`` fits parameter ``t`` on ``device``."""
    if on != device:
        raise ArgError(f"expected an array on device '{device}', got one on '{on}'")
    if dtype != t.dtype:
        raise ArgError(f"expected an array of {t.dtype}, got an array of {dtype}")
    if ndim != t.ndim:
        raise ArgError(f"expected a {t.ndim}-d array, got a {ndim}-d array")


def check_foreign(
    t: T.ArrayType, dtype: np.dtype, shape: tuple, what: str, fix: str = ".astype(np.{})"
) -> None:
    """Check a NumPy or CUDA-interface array: exact dtype, array dims + element dims.

    ``fix`` is the conversion to suggest, with ``{}`` for the wanted dtype's name.
    """
    if isinstance(t.dtype, T.StructType):  # a structured array in the struct's exact layout
        want_struct = T.storage_dtype(t.dtype)
        if dtype != want_struct or len(shape) != t.ndim:
            raise ArgError(
                f"expected a {t.ndim}-d array of {t.dtype} (NumPy dtype {want_struct}), got a "
                f"{what} {dtype} array of shape {tuple(shape)}"
            )
        return
    inner = T.value_shape(t.dtype)
    want = T.elem_type(t.dtype).np_dtype
    if dtype != want:
        raise ArgError(
            f"expected an array of {t.dtype} (NumPy {want}), got a {what} {dtype} "
            f"array; convert it with {fix.format(want)}"
        )
    outer = len(shape) - len(inner)
    if outer != t.ndim or tuple(shape[outer:]) != inner:
        want_shape = ("n",) * t.ndim + inner
        raise ArgError(
            f"expected a {t.ndim}-d array of {t.dtype} ({what} shape like "
            f"{want_shape}), got shape {tuple(shape)}".replace("'", "")
        )


def convert_scalar(t: T.ScalarType, value: Any) -> Any:
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value[()]
    if isinstance(value, np.generic):
        if value.dtype != t.np_dtype:
            raise ArgError(
                f"expected {t}, got NumPy {value.dtype} (NumPy scalars must match exactly)"
            )
        return value
    if t.is_bool:
        if isinstance(value, builtins.bool):
            return np.bool_(value)
    elif isinstance(value, builtins.bool):
        pass  # True for a number parameter is almost always a mistake
    elif isinstance(value, builtins.int):
        if t.is_int:
            info = np.iinfo(t.np_dtype)
            if not info.min <= value <= info.max:
                raise ArgError(f"expected {t}, got {value}, which does not fit in {t}")
        return t.np_dtype.type(value)
    elif isinstance(value, builtins.float) and t.is_float:
        return t.np_dtype.type(value)
    elif isinstance(value, builtins.float):
        raise ArgError(f"expected {t}, got float {value!r}; pass an int (floats are not truncated)")
    raise ArgError(f"expected {t}, got {describe(value)}")


def convert_composite(t: T.Type, value: Any) -> np.ndarray:
    shape = T.value_shape(t)
    et = T.elem_type(t)
    vt = getattr(type(value), "__kdsl_type__", None)
    if isinstance(value, np.ndarray) and value.dtype != et.np_dtype:
        what = str(vt) if isinstance(vt, T.Type) else f"NumPy {value.dtype} array"
        raise ArgError(f"expected {t}, got {what}")
    if isinstance(value, list | tuple | np.ndarray):
        arr = np.asarray(value)
        if arr.dtype.kind not in "biuf":
            raise ArgError(f"expected {t}, got {describe(value)}")
        if arr.shape != shape:
            raise ArgError(
                f"expected {t} ({'x'.join(map(str, shape))} components), got "
                f"{'x'.join(map(str, arr.shape)) or 'a scalar'}"
            )
        if et.is_int and arr.dtype.kind == "f":
            raise ArgError(f"expected {t}, got float components")
        return np.array(arr, dtype=et.np_dtype)
    raise ArgError(f"expected {t}, got {describe(value)}")


def _struct(t: T.StructType, value: Any, device: Device) -> tuple:
    vt = getattr(type(value), "__kdsl_type__", None)
    if isinstance(vt, property):  # an indexedarray: its type depends on the instance
        vt = value.__kdsl_type__
    if isinstance(value, tuple) and len(value) == len(t.fields):
        parts = value
    elif vt == t:
        parts = tuple(getattr(value, name) for name, _ in t.fields)
    else:
        raise ArgError(f"expected {t}, got {describe(value)}")
    out = []
    for (name, ft), v in zip(t.fields, parts):
        if v is None and isinstance(ft, T.ArrayType):  # an unset array field: empty, as in Warp
            # Made on the launch's device, so no device check: its null pointer has no
            # owner to ask, and CuPy would label (and copy) it to the current GPU.
            out.append(_empty_array(ft, device))
            continue
        try:
            out.append(convert(ft, v, device))
        except ArgError as e:
            raise ArgError(f"field '{name}' of {t}: {e}") from None
    return tuple(out)


def _empty_array(t: T.ArrayType, device: Device) -> Any:
    """A buffer with no elements for an array field left None."""
    dt = T.storage_dtype(t.dtype)
    return mem.empty((0,) * t.ndim + dt.shape, dt.base, device)


def launch_error(kernel_name: str, index: int, param: str, message: str) -> KdslLaunchError:
    """The error for a bad argument, naming kernel and parameter."""
    return KdslLaunchError(f"kernel '{kernel_name}', argument {index} '{param}': {message}")
