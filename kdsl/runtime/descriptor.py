"""``ArrayDescriptor``: what ``from_torch(..., return_ctype=True)`` returns.

It is the launch path's own view of an array (a buffer, its element type, its
device) without the ``kdsl.array`` object around it: building one is a few
attribute stores, and ``kdsl.launch`` takes it wherever it takes an array.
"""

from __future__ import annotations

from typing import Any

from kdsl.ir import types as T
from kdsl.runtime.device import Device


class ArrayDescriptor:
    """A lightweight array for launches: ``buf`` (NumPy or CuPy, element dims appended),
    ``dtype`` (the IR element type), ``ndim`` and ``device``. Not a ``kdsl.array``."""

    __slots__ = ("buf", "device", "dtype", "ndim", "owner")

    def __init__(self, buf: Any, dtype: T.Type, device: Device, owner: Any = None) -> None:
        self.buf = buf
        self.dtype = dtype
        self.device = device
        self.ndim = buf.ndim - len(T.value_shape(dtype))
        self.owner = owner  # keeps the source (a tensor) alive as long as the descriptor

    @property
    def shape(self) -> tuple[int, ...]:
        """The array's dims (element dims left out)."""
        return tuple(self.buf.shape[: self.ndim])

    def __repr__(self) -> str:
        return f"ArrayDescriptor({self.dtype}, shape={self.shape}, device='{self.device}')"
