"""Array constructors in Warp's spellings: zeros, empty, full, ones, *_like, copy.

Every constructor takes ``device="cpu"``, ``"cuda"`` or ``"cuda:N"``; CUDA buffers
come from CuPy's memory pool and are filled on the device's current stream.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from kdsl.errors import KdslError
from kdsl.ir import types as T
from kdsl.runtime import cuda_memory as mem
from kdsl.runtime.array import array
from kdsl.runtime.device import get_device
from kdsl.runtime.dtypes import (
    dtype_of_value,
    host_value,
    inner_shape,
    normalize_shape,
    np_dtype,
    resolve_dtype,
)
from kdsl.runtime.graphs import state as graphs
from kdsl.runtime.stream import Stream, get_stream
from kdsl.runtime.tape import record_copy


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
    if dev.is_cuda and isinstance(t, T.StructType) and not _zero_or_unset(init):
        # CuPy holds structured buffers but cannot fill them: fill on the host, upload once.
        host = np.zeros(dims, np_dtype(t))
        if init is not None:
            host[...] = np.asarray(host_value(t, init), dtype=host.dtype)
        return array._wrap(mem.from_host(host, dev), t, dev, requires_grad)
    buf = mem.empty(dims + inner_shape(t), np_dtype(t), dev)
    if dev.is_cuda and init is not None and _zero_or_unset(init) and not graphs.ACTIVE:
        mem.zero_async(buf, dev)  # zeros: one memset on the device's stream, no upload
    elif dev.is_cuda and isinstance(t, T.StructType) and init is not None:
        with mem.scope(dev):  # zeros (in a capture): a memset on the device's stream
            buf.data.memset_async(0, buf.nbytes)
    elif init is not None:
        if isinstance(t, T.StructType):  # padding too: the same bytes as on cuda
            buf.view(np.uint8)[...] = 0
        try:
            value = np.asarray(host_value(t, init), dtype=buf.dtype)
        except ValueError as e:
            raise KdslError(f"cannot fill an array of {t} with {init!r}: {e}") from None
        with mem.scope(dev):
            try:
                if graphs.ACTIVE:
                    graphs.captured_fill(buf, dev, value, fresh=True)
                else:
                    buf[...] = mem.cupy().asarray(value) if dev.is_cuda else value
            except ValueError as e:
                raise KdslError(f"cannot fill an array of {t} with {init!r}: {e}") from None
    elif graphs.ACTIVE:
        graphs.captured_fill(buf, dev, None, fresh=True)
    return array._wrap(buf, t, dev, requires_grad)


def _zero_or_unset(init: Any) -> bool:
    """Whether a fill value leaves a new array unset (None) or all zero bytes (the int 0)."""
    return init is None or (type(init) is int and init == 0)


def _filled(name: str, fill: Any, doc: str):  # the inner signature is the return type
    """A constructor with Warp's signature whose arrays start as ``fill`` (None: unspecified)."""

    def constructor(
        shape: Any = None,
        dtype: Any = float,
        device: Any = None,
        requires_grad: bool = False,
        length: int | None = None,
        pinned: bool = False,
    ) -> array:
        return _make(shape, length, dtype, device, requires_grad, fill)

    constructor.__name__ = constructor.__qualname__ = name
    constructor.__doc__ = doc
    return constructor


zeros = _filled(
    "zeros", 0, "A zero-filled array; ``shape`` is an int or tuple (``length=`` also accepted)."
)
empty = _filled(
    "empty", None, "An array whose contents are unspecified (``length=`` also accepted)."
)
ones = _filled("ones", 1, "An array of ones.")


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
    """A contiguous copy of ``src`` (same shape and dtype), on ``device`` or ``src``'s."""
    out = _like(src, device, requires_grad, None)
    copy(out, src)
    if out.device.is_cpu and src.device.is_cuda:
        get_stream(src.device).synchronize()  # a new host array is ready when returned
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
    dest: array,
    src: array,
    dest_offset: int = 0,
    src_offset: int = 0,
    count: int = 0,
    stream: Stream | None = None,
) -> None:
    """Copy ``count`` elements (all of ``src`` when 0) between arrays on any devices.

    Elements are taken in row-major order. With a GPU side the copy is enqueued
    on ``stream`` (default: the destination's current stream when it is a GPU,
    else the source's) and ordered with the work of both devices' current
    streams. Copies to the CPU are asynchronous, as in Warp: call
    ``kdsl.synchronize()`` before reading the destination with ``numpy()``.
    """
    if not isinstance(dest, array) or not isinstance(src, array):
        raise KdslError("copy() takes two kdsl arrays")
    if dest._t != src._t:
        raise KdslError(f"copy() needs arrays of one dtype, got {dest._t} and {src._t}")
    if stream is not None and not isinstance(stream, Stream):
        raise KdslError(f"copy(): stream must be a kdsl.Stream, not {type(stream).__name__}")
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
    rec = graphs.cpu_recording(dest.device) if src.device.is_cpu else None
    if rec is not None:  # a CPU capture records the copy for its replays
        rec.record_host(graphs.copy_rows(dest_offset, src_offset, n, dest._inner), dest._buf,
                        src._buf)  # fmt: skip
    else:
        mem.copy_elements(
            dest._buf, dest.device, dest_offset, src._buf, src.device, src_offset, n,
            dest._inner, stream,
        )  # fmt: skip
    # On an active kdsl.Tape a copy between arrays with gradients is differentiable.
    record_copy(dest, src, dest_offset, src_offset, n)
