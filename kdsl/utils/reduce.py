"""``array_sum`` and ``array_inner``: sums and inner products, whole or along an axis."""

from __future__ import annotations

from typing import Any

import numpy as np

from kdsl.ir.types import elem_type
from kdsl.runtime.alloc import empty
from kdsl.runtime.array import array
from kdsl.types import class_of, type_of
from kdsl.utils.buffers import UtilsError, check_array, device_buffer, on_device, same_device


def array_sum(values, out=None, value_count: int | None = None, axis: int | None = None):
    """The sum of ``values`` (Warp's ``array_sum``); vectors and matrices sum component-wise.

    ``axis=None`` sums the first ``value_count`` elements (all by default) in element
    order and returns the sum (a float, or a vector/matrix value), or writes it to
    ``out[0]``. With ``axis``, sums along that dimension into ``out`` (made when None),
    whose shape is ``values.shape`` with ``axis`` of size 1 (as Warp's); ``value_count``
    then limits the elements taken along ``axis``. Elements must be float32 or float64 based.
    """
    a = check_array("values", values)
    return _reduce("array_sum", a, None, out, value_count, axis)


def array_inner(a, b, out=None, count: int | None = None, axis: int | None = None):
    """The inner product of ``a`` and ``b`` (Warp's ``array_inner``): the sum of the
    element-wise products, vector elements multiplied as dot products.

    Shapes, ``count`` and ``axis`` work as in ``array_sum``; the result has the arrays'
    scalar type.
    """
    x, y = check_array("a", a), check_array("b", b)
    if x.shape != y.shape or x.dtype is not y.dtype:
        raise UtilsError(f"a and b must have one shape and dtype, got {x.shape} {x.dtype} and "
                         f"{y.shape} {y.dtype}")  # fmt: skip
    return _reduce("array_inner", x, y, out, count, axis)


class SumInto:
    """A prepared ``array_sum(values, out=out)`` for arrays summed again and again (a
    mesh's edge lengths at every refit): the checks and the buffer views are made once,
    each call is one reduction on the device and a one-element store, the very
    operations of ``array_sum`` (the same bits). ``values`` is a contiguous 1-d float
    array, ``out`` a one-element array of its dtype on its device."""

    __slots__ = ("_out", "_owner", "_values", "_xp")

    def __init__(self, values: array, out: array) -> None:
        a = check_array("values", values)
        same_device(values=a, out=out)
        t = type_of(a.dtype)
        if a.ndim != 1 or not a.is_contiguous or elem_type(t) != t or t.np_dtype.kind != "f":
            raise UtilsError(f"SumInto needs a contiguous 1-d float array, not {a.dtype} of "
                             f"shape {a.shape}")  # fmt: skip
        _check_out("SumInto", out, a, (1,))
        self._owner = a  # for the device scope
        self._xp, self._values = device_buffer(a)
        self._out = device_buffer(out)[1]

    def __call__(self) -> None:
        """Write the sum of ``values`` into ``out[0]`` (on the device's kdsl stream)."""
        with on_device(self._owner):
            # array_sum's own two operations (a sum, then a store), so the same bits.
            self._out[...] = self._xp.sum(self._values, axis=0, dtype=self._values.dtype)


def _reduce(what: str, a: array, b: array | None, out: Any, count: int | None, axis: int | None):
    same_device(a=a, b=b, out=out)
    elem = elem_type(type_of(a.dtype))
    if elem.np_dtype.kind != "f":
        raise UtilsError(f"{what} supports float32- and float64-based elements, not {a.dtype}")
    if axis is not None:
        if not -a.ndim <= axis < a.ndim:
            raise IndexError(f"{what}: axis {axis} is out of range for a {a.ndim}-d array")
        axis %= a.ndim
    xp, x = device_buffer(a)
    y = None if b is None else device_buffer(b)[1]
    with on_device(a):
        inner = x.shape[a.ndim :]
        if axis is None:
            n = a.size if count is None else _count(what, count, a.size)
            x = x.reshape((a.size, *inner))[:n]
            y = None if y is None else y.reshape((a.size, *inner))[:n]
            total = _combine(xp, x, y, 0, len(inner))
            if out is None:
                return _value(a, b, total)
            _check_out(what, out, a if b is None else None, (1,))
            _store(out, total.reshape((1, *total.shape)))
            return out
        n = a.shape[axis] if count is None else _count(what, count, a.shape[axis])
        sl = (slice(None),) * axis + (slice(0, n),)
        total = _combine(xp, x[sl], None if y is None else y[sl], axis, len(inner))
        shape = (*a.shape[:axis], 1, *a.shape[axis + 1 :])  # Warp keeps the axis, of size 1
        if out is None:
            dtype = a.dtype if b is None else class_of(elem)
            out = empty(shape, dtype=dtype, device=a.device)
        _check_out(what, out, a if b is None else None, shape)
        _store(out, total.reshape(out.shape + total.shape[len(shape) - 1 :]))
        return out


def _combine(xp: Any, x: Any, y: Any, axis: int, inner_dims: int) -> Any:
    if y is None:
        return xp.sum(x, axis=axis, dtype=x.dtype)
    prod = x * y
    if inner_dims:  # dot products of vector/matrix elements first
        prod = prod.reshape((*prod.shape[: prod.ndim - inner_dims], -1)).sum(axis=-1)
    return xp.sum(prod, axis=axis, dtype=x.dtype)


def _value(a: array, b: array | None, total: Any) -> Any:
    host = total.get() if hasattr(total, "get") else np.asarray(total)
    if b is not None or host.ndim == 0:
        return float(host)
    return a.dtype(host)


def _count(what: str, count: Any, limit: int) -> int:
    if (
        isinstance(count, bool)
        or not isinstance(count, int | np.integer)
        or not 0 <= count <= limit
    ):
        raise UtilsError(f"{what}: count must be an int in [0, {limit}], got {count!r}")
    return int(count)


def _check_out(what: str, out: Any, like: array | None, shape: tuple) -> None:
    check_array("out", out)
    if tuple(out.shape) != tuple(shape):
        raise UtilsError(f"{what}: out must have shape {shape}, got {out.shape}")
    if like is not None and out.dtype is not like.dtype:
        raise UtilsError(f"{what}: out must hold {like.dtype}, not {out.dtype}")


def _store(out: array, values: Any) -> None:
    device_buffer(out)[1][...] = values
