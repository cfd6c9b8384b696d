"""Seeing a foreign buffer as a kdsl array: dtype, element dims and layout checks.

A buffer (NumPy or CuPy) wrapping another framework's memory is checked once
here and reinterpreted without copying: a kdsl vector or matrix dtype takes the
buffer's trailing dims as its components (a ``(n, 3)`` float32 tensor with
``dtype=vec3`` is a length-n ``vec3`` array), and integer data may be seen as
the other signedness of the same width (frameworks without uint32 hand kdsl
int32 data for uint32 arrays).
"""

from __future__ import annotations

from typing import Any

from kdsl.errors import KdslError
from kdsl.interop.dtypes import InteropTypeError, scalar_from_numpy_dtype
from kdsl.ir import types as T
from kdsl.runtime.array import array
from kdsl.runtime.device import Device
from kdsl.runtime.dtypes import resolve_dtype
from kdsl.types import class_of


class InteropLayoutError(KdslError, ValueError):
    """Foreign data whose shape or strides cannot be seen as the asked kdsl array."""


def _same_width_ints(a: Any, b: Any) -> bool:
    return a.kind in "iu" and b.kind in "iu" and a.itemsize == b.itemsize


def element_type(buf: Any, dtype: Any, what: str) -> T.Type:
    """The IR element type for ``buf``: ``dtype`` resolved, or the buffer's own scalar."""
    if dtype is None:
        return scalar_from_numpy_dtype(buf.dtype, what)
    return resolve_dtype(dtype)


def view_buffer(buf: Any, dtype: Any, what: str) -> tuple[Any, T.Type]:
    """``buf`` checked (and reinterpreted when needed) as an array of ``dtype``.

    ``what`` describes the source for messages ("torch.float64 tensor of shape (4, 3)").
    Returns the buffer to wrap and the IR element type.
    """
    t = element_type(buf, dtype, what)
    want = T.elem_type(t).np_dtype
    if buf.dtype != want:
        if not _same_width_ints(buf.dtype, want):
            name = class_of(t).__name__
            raise InteropTypeError(
                f"cannot view a {what} as an array of {name}: its components are "
                f"{want.name}; convert the data to {want.name} first"
            )
        buf = buf.view(want)
    inner = T.value_shape(t)
    k = len(inner)
    if k and tuple(buf.shape[buf.ndim - k :]) != inner:
        raise InteropLayoutError(
            f"cannot view a {what} as an array of {class_of(t).__name__}: its last "
            f"{'dim' if k == 1 else f'{k} dims'} must be {inner if k > 1 else inner[0]}"
        )
    if k and buf.size:
        packed, step = [], want.itemsize
        for n in reversed(inner):
            packed.insert(0, step)
            step *= n
        have = buf.strides[buf.ndim - k :]
        # A dim of extent 1 is never stepped over, so its stride does not matter.
        if any(n > 1 and h != p for n, h, p in zip(inner, have, packed)):
            raise InteropLayoutError(
                f"cannot view a {what} as an array of {class_of(t).__name__}: the "
                f"components of each element must be contiguous in memory (strides "
                f"{tuple(buf.strides)} bytes); make the data contiguous first "
                f"(.contiguous() in PyTorch)"
            )
    outer = buf.ndim - k
    if not 1 <= outer <= 4:
        raise InteropLayoutError(
            f"cannot view a {what} as a kdsl array: arrays have 1 to 4 dims, this gives {outer}"
        )
    return buf, t


def wrap(buf: Any, dtype: Any, device: Device, what: str) -> array:
    """A ``kdsl.array`` over ``buf`` (no copy), after ``view_buffer``'s checks."""
    buf, t = view_buffer(buf, dtype, what)
    return array._wrap(buf, t, device)


def describe_buffer(dtype_name: str, kind: str, shape: Any) -> str:
    """``"torch.float64 tensor of shape (4, 3)"``, for messages."""
    return f"{dtype_name} {kind} of shape {tuple(shape)}"
