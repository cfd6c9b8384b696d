"""Array constructors in Warp's spellings: zeros, empty, full, ones, *_like, copy."""

from __future__ import annotations

from typing import Any

import numpy as np

from kdsl.errors import KdslError
from kdsl.runtime.array import array
from kdsl.runtime.device import get_device
from kdsl.runtime.dtypes import (
    dtype_of_value,
    inner_shape,
    normalize_shape,
    np_dtype,
    resolve_dtype,
)


def _dims(shape: Any, length: Any) -> tuple[int, ...]:
    # Old Warp code says zeros(length=n); new code says zeros(n) or zeros((n, m)).
    if shape is None:
        shape = 0 if length is None else length
    return normalize_shape(shape)


def _make(
    shape: Any, length: Any, dtype: Any, device: Any, requires_grad: bool, init: Any
) -> array:
    t = resolve_dtype(dtype)
    dims = _dims(shape, length)
    dev = get_device(device)
    if not dev.is_cpu:
        raise KdslError(f"arrays on device '{dev}' are not supported yet; use device='cpu'")
    buf = np.empty(dims + inner_shape(t), np_dtype(t))
    if init is not None:
        try:
            buf[...] = np.asarray(init, dtype=buf.dtype)
        except ValueError as e:
            raise KdslError(f"cannot fill an array of {t} with {init!r}: {e}") from None
    return array._wrap(buf, t, dev, requires_grad)


def zeros(
    shape: Any = None,
    dtype: Any = float,
    device: Any = None,
    requires_grad: bool = False,
    length: int | None = None,
    pinned: bool = False,
) -> array:
    """A zero-filled array; ``shape`` is an int or tuple (``length=`` also accepted)."""
    return _make(shape, length, dtype, device, requires_grad, 0)


def empty(
    shape: Any = None,
    dtype: Any = float,
    device: Any = None,
    requires_grad: bool = False,
    length: int | None = None,
    pinned: bool = False,
) -> array:
    """An array whose contents are unspecified (``length=`` also accepted)."""
    return _make(shape, length, dtype, device, requires_grad, None)


def full(
    shape: Any = None,
    value: Any = 0,
    dtype: Any = Any,
    device: Any = None,
    requires_grad: bool = False,
    length: int | None = None,
    pinned: bool = False,
) -> array:
    """An array with every element ``value``; the dtype is inferred from it if not given."""
    if dtype is Any or dtype is None:
        dtype = dtype_of_value(value)
    return _make(shape, length, dtype, device, requires_grad, value)


def ones(
    shape: Any = None,
    dtype: Any = float,
    device: Any = None,
    requires_grad: bool = False,
    length: int | None = None,
    pinned: bool = False,
) -> array:
    """An array of ones."""
    return _make(shape, length, dtype, device, requires_grad, 1)


def _like(src: array, device: Any, requires_grad: bool | None, init: Any) -> array:
    dev = src.device if device is None else device
    rg = src.requires_grad if requires_grad is None else requires_grad
    return _make(src.shape, None, src._t, dev, rg, init)


def zeros_like(src: array, device: Any = None, requires_grad: bool | None = None) -> array:
    """A zero array with the shape and dtype of ``src``."""
    return _like(src, device, requires_grad, 0)


def ones_like(src: array, device: Any = None, requires_grad: bool | None = None) -> array:
    """An array of ones with the shape and dtype of ``src``."""
    return _like(src, device, requires_grad, 1)


def empty_like(src: array, device: Any = None, requires_grad: bool | None = None) -> array:
    """An uninitialized array with the shape and dtype of ``src``."""
    return _like(src, device, requires_grad, None)


def full_like(
    src: array, value: Any, device: Any = None, requires_grad: bool | None = None
) -> array:
    """An array with the shape and dtype of ``src`` filled with ``value``."""
    return _like(src, device, requires_grad, value)


def clone(src: array, device: Any = None, requires_grad: bool | None = None) -> array:
    """A copy of ``src`` (same shape and dtype; contiguous)."""
    out = _like(src, device, requires_grad, None)
    out._buf[...] = src._buf
    return out


def from_numpy(
    arr: Any, dtype: Any = None, shape: Any = None, device: Any = None, requires_grad: bool = False
) -> array:
    """An array holding a copy of NumPy ``arr``.

    With a vector or matrix ``dtype`` the trailing dims of ``arr`` are the
    components: an ``(n, 3)`` array with ``dtype=vec3`` gives a length-n array.
    """
    return array(
        np.asarray(arr),
        dtype=dtype,
        shape=shape,
        device=device,
        requires_grad=requires_grad,
        copy=True,
    )


def copy(
    dest: array, src: array, dest_offset: int = 0, src_offset: int = 0, count: int = 0
) -> None:
    """Copy ``count`` elements (all of ``src`` when 0) between arrays, in row-major order."""
    if not isinstance(dest, array) or not isinstance(src, array):
        raise KdslError("copy() takes two kdsl arrays")
    if dest._t != src._t:
        raise KdslError(f"copy() needs arrays of one dtype, got {dest._t} and {src._t}")
    n = count or src.size - src_offset
    if (
        src_offset + n > src.size
        or dest_offset + n > dest.size
        or min(src_offset, dest_offset, n) < 0
    ):
        raise KdslError(
            f"copy() of {n} elements from offset {src_offset} of {src.size} to offset "
            f"{dest_offset} of {dest.size} is out of range"
        )
    inner = dest._inner
    flat_src = src._buf.reshape(-1, *inner)
    flat_dest = dest._buf.reshape(-1, *inner)
    flat_dest[dest_offset : dest_offset + n] = flat_src[src_offset : src_offset + n]
    if not np.shares_memory(flat_dest, dest._buf):  # strided dest: reshape made a copy
        dest._buf[...] = flat_dest.reshape(dest._buf.shape)
