"""What the optimizers share: their errors, the dtypes they update, and argument checks.

A parameter array may hold floats (``float16``, ``float32``, ``float64``) or vectors or
matrices of them. The update runs in the parameter's own precision, except for
``float16`` elements, which are updated in ``float32`` (the moments and the step) and
rounded back, as Warp's Adam does. The update kernels take one-dimensional arrays, as
Warp's do; an n-dimensional contiguous array is updated through its flat view.
"""

from __future__ import annotations

import numbers
from collections.abc import Sequence
from typing import Any

from kdsl.errors import KdslError
from kdsl.ir import types as T
from kdsl.runtime.alloc import zeros
from kdsl.runtime.array import array
from kdsl.types import class_of, type_of


class OptimError(KdslError, RuntimeError):
    """A bad argument to a ``kdsl.optim`` optimizer (a ``RuntimeError`` too, as in Warp)."""


class OptimTypeError(OptimError, TypeError):
    """A gradient or buffer whose dtype is not the parameter's (a ``TypeError``, as in Warp)."""


class OptimShapeError(OptimError, ValueError):
    """A gradient whose shape is not the parameter's (a ``ValueError``, as in Warp)."""


def value_type(dtype: Any, quats: bool = False) -> T.Type | None:
    """The IR type of a parameter dtype the optimizers update, or None.

    ``quats``: quaternions count too (SGD's update is a linear combination, which Warp's
    SGD applies to quaternions component-wise; Adam's squares do not apply to them).
    """
    try:
        t = type_of(dtype)
    except TypeError:
        return None
    if quats and isinstance(t, T.QuatType) and t.elem.is_float:
        return t
    if isinstance(t, T.QuatType | T.TransformType):  # not componentwise values
        return None
    if isinstance(t, T.ScalarType | T.VectorType | T.MatrixType) and T.elem_type(t).is_float:
        return t
    return None


def compute_type(t: T.Type) -> T.Type:
    """The type the update computes in: ``t``, with ``float16`` elements widened to f32."""
    return T.with_elem(t, T.F32) if T.elem_type(t) == T.F16 else t


def scalar_class(t: T.Type) -> type:
    """The class of the update's scalar arguments (lr, betas, ...): f64 for f64 elements."""
    return class_of(T.elem_type(compute_type(t)))


def type_name(dtype: Any) -> str:
    return getattr(dtype, "__name__", repr(dtype))


def check_params(who: str, params: Any, quats: bool = False) -> list[array] | None:
    """``params`` as a list of kdsl arrays of supported dtypes (None stays None);
    ``quats`` as in ``value_type``."""
    if params is None:
        return None
    if isinstance(params, array) or not isinstance(params, Sequence):
        raise OptimError(f"{who} params must be a list of kdsl arrays, got {type(params).__name__}")
    for i, p in enumerate(params):
        if not isinstance(p, array):
            raise OptimError(f"{who} params[{i}] must be a kdsl array, got {type(p).__name__}")
        if value_type(p.dtype, quats) is None:
            raise OptimError(
                f"{who} params[{i}] has dtype {type_name(p.dtype)}; supported are float16, "
                f"float32, float64 and vectors{', quaternions' if quats else ''} and "
                "matrices of them"
            )
        flat(p, f"{who} params[{i}]")
    return list(params)


def check_number(who: str, name: str, value: Any) -> float:
    """``value`` as a float, or an ``OptimError`` naming the hyperparameter."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise OptimError(f"{who} {name} must be a real number, got {value!r}")
    return float(value)


def check_like(who: str, name: str, a: Any, params: array) -> None:
    """Refuse ``a`` (a gradient or buffer) unless it is an array like ``params``."""
    if not isinstance(a, array):
        raise OptimError(f"{who} {name} must be a kdsl array, got {type(a).__name__}")
    if a.dtype != params.dtype:
        raise OptimTypeError(
            f"{who} {name} dtype must match parameter dtype {type_name(params.dtype)}, "
            f"got {type_name(a.dtype)}"
        )
    if a.shape != params.shape:
        raise OptimShapeError(
            f"{who} {name} shape must match parameter shape {params.shape}, got {a.shape}"
        )
    if a.device != params.device:
        raise OptimError(
            f"{who} {name} is on device '{a.device}', the parameter on '{params.device}'"
        )


def check_buffer(who: str, name: str, buf: Any, params: array, dtype: Any) -> None:
    """Refuse a moment buffer unless it is an array of ``dtype`` shaped like ``params``."""
    if not isinstance(buf, array):
        raise OptimError(f"{who} {name} must be a kdsl array, got {type(buf).__name__}")
    if buf.dtype != dtype:
        raise OptimTypeError(
            f"{who} {name} dtype must be {type_name(dtype)}, got {type_name(buf.dtype)}"
        )
    if buf.shape != params.shape or buf.device != params.device:
        raise OptimShapeError(
            f"{who} {name} must have the parameter's shape {params.shape} on '{params.device}', "
            f"got {buf.shape} on '{buf.device}'"
        )


def flat(a: array, name: str) -> array:
    """``a`` as a one-dimensional array over the same memory."""
    if a.ndim == 1:
        return a
    if not a.is_contiguous:
        raise OptimError(f"{name} must be contiguous or one-dimensional (shape {a.shape})")
    return a.flatten()


def list_of(who: str, name: str, values: Any, count: int) -> list[Any]:
    """``values`` as a list of ``count`` entries, or an ``OptimError``."""
    if isinstance(values, array) or not isinstance(values, Sequence):
        raise OptimError(f"{who} {name} must be a list of kdsl arrays, got {type(values).__name__}")
    if len(values) != count:
        raise OptimError(f"{who} got {len(values)} {name} arrays for {count} parameter arrays")
    return list(values)


def fitted(buffers: list[array | None], params: list[array], dtype_of: Any) -> list[array]:
    """``buffers`` made to fit ``params`` as Warp's optimizers keep them: one per
    parameter, zeros of ``dtype_of(p)`` and ``p``'s shape where missing or no longer of
    that shape and dtype, moved to ``p``'s device where it moved."""
    out = list(buffers) if len(buffers) == len(params) else [None] * len(params)
    for i, p in enumerate(params):
        buf, dtype = out[i], dtype_of(p)
        if buf is None or buf.shape != p.shape or buf.dtype != dtype:
            out[i] = zeros(p.shape, dtype=dtype, device=p.device)
        elif buf.device != p.device:
            out[i] = buf.to(p.device)
    return out


def zero_all(buffers: list[array | None]) -> None:
    """Zero every buffer of ``buffers`` (``reset_internal_state``)."""
    for buf in buffers:
        if buf is not None:
            buf.zero_()
