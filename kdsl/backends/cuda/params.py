"""Kernel parameters: packed once per launch into one buffer, with little Python work.

Each kernel gets a ``Packer`` built once from its signature: a ``struct.Struct``
format covering every C parameter at its offset (natural C alignment, explicit
padding), and one small function per argument that flattens the launch value
into that format's fields. A launch packs all fields with one ``pack_into`` and
builds the ``kernelParams`` array of pointers into the buffer. CUDA copies the
parameters when the launch is enqueued, so the buffer may die right after.

Array arguments are CuPy arrays: their descriptor is (data pointer, shape, strides
in bytes). An array on another GPU than the launch is refused.
"""

from __future__ import annotations

import ctypes
import functools
import struct
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from kdsl.backends.cuda import ctypes_ as CT
from kdsl.backends.param_writer import Writers, make_writer
from kdsl.errors import KdslLaunchError
from kdsl.ir import types as T

#: The launch grid parameter: ``struct kd_grid { unsigned n; unsigned dim[4]; }``.
_GRID_FMT = "IIIII"


class _Layout:
    """Builds a format string with C alignment, tracking the offset."""

    def __init__(self) -> None:
        self.fmt: list[str] = []
        self.offset = 0

    def align(self, a: int) -> None:
        pad = (-self.offset) % a
        if pad:
            self.fmt.append(f"{pad}x")
            self.offset += pad

    def add(self, t: T.Type) -> None:
        """Append the fields of a value of ``t`` (aligned as C aligns it, padded to its size)."""
        size, align = CT.layout(t)
        self.align(align)
        end = self.offset + size
        if isinstance(t, T.StructType):
            for _, ft in t.fields:
                self.add(ft)
            if end > self.offset:  # trailing padding of the struct
                self.fmt.append(f"{end - self.offset}x")
        elif isinstance(t, T.ScalarType):
            self.fmt.append(t.struct)
        elif isinstance(t, T.VectorType | T.MatrixType):
            self.fmt.append(f"{CT.count(t)}{t.elem.struct}")
        elif isinstance(t, T.ArrayType):
            self.fmt.append(f"Q{2 * t.ndim}q")
        else:  # a handle
            self.fmt.append("Q")
        self.offset = end


def _flattener(t: T.Type, index: int, name: str) -> Callable[[Any, list, int], None]:
    """A function appending the fields of a launch value of ``t`` to a list."""
    if isinstance(t, T.ArrayType):
        nd = t.ndim
        dt = T.storage_dtype(t.dtype)  # a struct element is one opaque record: no inner dims
        item, inner = dt.base.itemsize, dt.shape
        want = tuple(int(np.prod(inner[k + 1 :], dtype=np.int64)) * item for k in range(len(inner)))

        if nd == 1 and not want:  # the common case, inline: a 1-d array of scalars

            def array_1d(a: Any, out: list, device: int) -> None:
                data = a.data
                if data.device_id != device:
                    raise KdslLaunchError(
                        f"argument {index} ('{name}') is an array on cuda:{data.device_id}, "
                        f"but the launch runs on cuda:{device}"
                    )
                out += (data.ptr, a.shape[0], a.strides[0])

            return array_1d

        def array(a: Any, out: list, device: int) -> None:
            if a.data.device_id != device:
                raise KdslLaunchError(
                    f"argument {index} ('{name}') is an array on cuda:{a.data.device_id}, but "
                    f"the launch runs on cuda:{device}"
                )
            strides = a.strides
            if want and tuple(strides[nd:]) != want and a.size:
                raise KdslLaunchError(
                    f"argument {index} ('{name}'): the cuda backend needs the {t.dtype} "
                    f"components of each element to be contiguous (strides {strides})"
                )
            out.append(a.data.ptr)
            out.extend(a.shape[:nd])
            out.extend(strides[:nd])

        return array
    if isinstance(t, T.StructType):
        parts = [_flattener(ft, index, name) for _, ft in t.fields]

        def struct_(v: Any, out: list, device: int) -> None:
            for p, x in zip(parts, v):
                p(x, out, device)

        return struct_
    if isinstance(t, T.VectorType | T.MatrixType):
        dtype = t.elem.np_dtype

        def vector(v: Any, out: list, device: int) -> None:
            out.extend(np.asarray(v, dtype=dtype).ravel().tolist())

        return vector

    def scalar(v: Any, out: list, device: int) -> None:
        out.append(v)

    return scalar


class Packer:
    """Packs one kernel's launch arguments (see the module docstring)."""

    def __init__(self, types: Sequence[T.Type], names: Sequence[str], debug: bool) -> None:
        self.types = list(types)
        lay = _Layout()
        self.offsets: list[int] = []
        #: Per parameter, its fields' format (from its offset) and its size in bytes.
        self.fields: list[tuple[str, int]] = []
        for t in types:
            lay.align(CT.layout(t)[1])
            self.offsets.append(lay.offset)
            first = len(lay.fmt)
            lay.add(t)
            self.fields.append(("".join(lay.fmt[first:]), lay.offset - self.offsets[-1]))
        lay.align(4)
        self.offsets.append(lay.offset)
        lay.fmt.append(_GRID_FMT)
        lay.offset += 4 * len(_GRID_FMT)
        if debug:
            lay.align(8)
            self.offsets.append(lay.offset)
            lay.fmt.append("Q")
            lay.offset += 8
        self.struct = struct.Struct("<" + "".join(lay.fmt))
        self.size = max(self.struct.size, 1)
        self.flatteners = [_flattener(t, i, n) for i, (t, n) in enumerate(zip(types, names))]
        self.ptr_array = ctypes.c_void_p * len(self.offsets)
        #: Writes the pointer table (cheaper than ``ptr_array(*pointers)``).
        self._table = struct.Struct(f"<{len(self.offsets)}Q")
        self._writers = Writers(self._make_writer)

    def pack(
        self, args: Sequence[Any], device: int, grid: Sequence[int], record: int | None = None
    ) -> tuple[Any, Any]:
        """(buffer, kernelParams array); keep both alive until the launch is enqueued."""
        vals: list = []
        for f, a in zip(self.flatteners, args):
            f(a, vals, device)
        vals.extend(grid)
        if record is not None:
            vals.append(record)
        buf = ctypes.create_string_buffer(self.size)
        try:
            self.struct.pack_into(buf, 0, *vals)
        except struct.error as e:
            raise KdslLaunchError(f"cannot pass the launch arguments to the kernel: {e}") from None
        base = ctypes.addressof(buf)
        table = self.ptr_array()
        self._table.pack_into(table, 0, *[base + o for o in self.offsets])
        return buf, table

    def writer(self, indices: Sequence[int]) -> Callable[[Any, Sequence[Any]], None]:
        """A function writing new values of the by-value parameters ``indices`` (scalars,
        vectors, matrices, handles; ascending) into a buffer ``pack`` filled, in place:
        ``write(buf, values)``, one value per index (``param_writer.make_writer``). Made
        once per set of indices (every patchable launch of the kernel asks)."""
        return self._writers.get(indices)

    def _make_writer(self, indices: Sequence[int]) -> Callable[[Any, Sequence[Any]], None]:
        flatten: list = [None] * len(self.types)
        for i in indices:
            t = self.types[i]
            if isinstance(t, T.ArrayType | T.StructType):
                raise TypeError(f"parameter {i} is a {t}, not a by-value parameter")
            if isinstance(t, T.VectorType | T.MatrixType):
                flatten[i] = functools.partial(_flatten_composite, self.flatteners[i])
        return make_writer(indices, self.offsets, self.fields, flatten)


def _flatten_composite(flattener: Callable[[Any, list, int], None], v: Any, out: list) -> None:
    """A vector's or matrix's fields, by its ``_flattener`` (which needs no device)."""
    flattener(v, out, -1)
