"""Launch arguments in the memory layout the generated range functions read.

See ``lower`` for the layout: ``args[k]`` points at an array descriptor (data
pointer, shape, strides in scalar elements), a scalar or vector, or an array of
field pointers for a struct. The NumPy buffers built here must stay alive for
the whole launch; ``Packed`` holds them.
"""

from __future__ import annotations

import ctypes
import functools
import struct
import threading
import weakref
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from kdsl.backends.param_writer import Writers, make_writer
from kdsl.errors import KdslLaunchError
from kdsl.ir import types as T


class Packed:
    """The ``args`` pointer array of one launch and everything it points into."""

    def __init__(
        self, types: Sequence[T.Type], values: Sequence[Any], extra: Sequence[int] = ()
    ) -> None:
        """Pack ``values``; ``extra`` raw pointers follow them (a debug build's error record)."""
        self.keep: list[Any] = []
        ptrs = [self._pack(t, v, i) for i, (t, v) in enumerate(zip(types, values))]
        ptrs += list(extra)
        self.array = (ctypes.c_void_p * max(1, len(ptrs)))(*ptrs)
        self.address = ctypes.addressof(self.array)

    def _hold(self, arr: np.ndarray) -> int:
        self.keep.append(arr)
        return arr.ctypes.data

    def _pack(self, t: T.Type, value: Any, index: int) -> int:
        if isinstance(t, T.ArrayType):
            return self._hold(descriptor(t, value, index))
        if isinstance(t, T.StructType):
            fields = [self._pack(ft, v, index) for (_, ft), v in zip(t.fields, value)]
            arr = (ctypes.c_void_p * max(1, len(fields)))(*fields)
            self.keep.append(arr)
            return ctypes.addressof(arr)
        if isinstance(t, T.HandleType):
            return self._hold(np.array([value], dtype=np.uint64))
        dtype = T.elem_type(t).np_dtype
        return self._hold(np.ascontiguousarray(np.asarray(value, dtype=dtype).reshape(-1)))


def descriptor(t: T.ArrayType, buf: np.ndarray, index: int = 0) -> np.ndarray:
    """The descriptor of a NumPy buffer: [data, shape..., strides in elements...].

    Arrays of structs count their strides in bytes (an element is a byte to the
    generated code, which adds the fields' ``storage_dtype`` offsets).
    """
    return np.array(descriptor_words(t, buf, index), dtype=np.int64)


@functools.lru_cache(maxsize=256)
def _array_layout(t: T.ArrayType) -> tuple[int, int, tuple[int, ...]]:
    """(element size for strides, ndim, the byte strides the element's components need)."""
    is_struct = isinstance(t.dtype, T.StructType)
    item = 1 if is_struct else T.elem_type(t.dtype).np_dtype.itemsize
    inner = () if is_struct else T.value_shape(t.dtype)
    want, step = [], item
    for n in reversed(inner):
        want.append(step)
        step *= n
    return item, t.ndim, tuple(reversed(want))


def descriptor_words(t: T.ArrayType, buf: np.ndarray, index: int = 0) -> tuple[int, ...]:
    """``descriptor`` as a tuple of ints (what the argument packer writes)."""
    item, nd, want = _array_layout(t)
    all_strides = buf.strides
    if all_strides[nd:] != want and buf.size:
        raise KdslLaunchError(
            f"argument {index}: the cpu backend needs the {t.dtype} components of each "
            f"element to be contiguous (strides {all_strides})"
        )
    strides = all_strides[:nd]
    if any(s % item for s in strides):
        raise KdslLaunchError(
            f"argument {index}: strides {strides} are not multiples of the element "
            f"size {item}; the cpu backend cannot address this array"
        )
    data = buf.__array_interface__["data"][0]
    return (data, *buf.shape[:nd], *[s // item for s in strides])


# --- the fast path: one struct.pack_into per launch -----------------------------------

#: Array descriptors by ``id`` of their NumPy buffer, checked through a weak reference
#: and against the buffer's shape and strides (a NumPy array can be reshaped in place):
#: reading a buffer's address from NumPy costs about a microsecond, so a kernel
#: launched again and again on the same arrays computes each descriptor once.
_descriptors: dict[int, tuple[weakref.ref, tuple, tuple, tuple[int, ...]]] = {}


def _cached_descriptor(t: T.ArrayType, buf: np.ndarray, index: int) -> tuple[int, ...]:
    hit = _descriptors.get(id(buf))
    if hit is not None and hit[0]() is buf and hit[1] == buf.shape and hit[2] == buf.strides:
        return hit[3]
    words = descriptor_words(t, buf, index)
    key = id(buf)
    try:
        ref = weakref.ref(buf, lambda _r, key=key: _descriptors.pop(key, None))
    except TypeError:  # not weak-referenceable: never cache
        return words
    _descriptors[key] = (ref, buf.shape, buf.strides, words)
    return words


class ArgPacker:
    """Packs the arguments of one kernel signature into a reusable buffer.

    The layout is fixed per signature: the pointer table (one slot per argument,
    plus ``extra`` raw-pointer slots) followed by each argument's bytes at a
    16-byte-aligned offset. The table is written once per buffer, so a launch is
    one ``struct.pack_into`` of the argument values. Signatures with struct
    parameters fall back to ``Packed`` (``supported`` is False).
    """

    def __init__(self, types: Sequence[T.Type], extra: int = 0) -> None:
        self.types = list(types)
        self.extra = extra
        self.supported = not any(isinstance(t, T.StructType) for t in self.types)
        nslots = max(1, len(self.types) + extra)
        # The values start after the table; ``struct`` writes its pad bytes, so the
        # format covers only the values and is packed at ``self.start``.
        self.start = offset = _align(8 * nslots)
        fmt, self.offsets, self._kinds = ["<"], [], []
        pos = offset
        for t in self.types if self.supported else ():
            pad = offset - pos
            if pad:
                fmt.append(f"{pad}x")
            self.offsets.append(offset)
            size, code, kind = _layout(t)
            fmt.append(code)
            self._kinds.append(kind)
            pos = offset + size
            offset = _align(pos)
        for _ in range(extra):  # extra pointers live in their own slots after the args
            pad = offset - pos
            if pad:
                fmt.append(f"{pad}x")
            self.offsets.append(offset)
            fmt.append("Q")
            pos = offset + 8
            offset = _align(pos)
        self.struct = struct.Struct("".join(fmt))
        self.size = self.start + self.struct.size
        self._local = threading.local()
        self._writers = Writers(self._make_writer)

    def new_buffer(self) -> Any:
        """A fresh argument buffer with its pointer table filled in."""
        buf = ctypes.create_string_buffer(self.size)
        base = ctypes.addressof(buf)
        table = (ctypes.c_uint64 * len(self.offsets)).from_buffer(buf)
        for k, off in enumerate(self.offsets):
            table[k] = base + off
        return buf

    def thread_buffer(self) -> Any:
        """This thread's buffer: launches are synchronous, so a thread can reuse one."""
        buf = getattr(self._local, "buf", None)
        if buf is None:
            buf = self._local.buf = self.new_buffer()
        return buf

    def flatten(self, values: Sequence[Any]) -> list:
        """The argument values as the flat list ``struct`` packs."""
        out: list = []
        for k, (t, kind, v) in enumerate(zip(self.types, self._kinds, values)):
            if kind == "array":
                out.extend(_cached_descriptor(t, v, k))
            elif kind == "scalar":
                out.append(v)
            elif kind == "handle":
                out.append(int(v))
            else:
                out.extend(np.asarray(v).reshape(-1).tolist())
        return out

    def pack_into(self, buf: Any, values: Sequence[Any], extra: Sequence[int] = ()) -> int:
        """Write ``values`` (and ``extra`` pointers) into ``buf``; returns its address."""
        flat = self.flatten(values)
        flat.extend(extra)
        self.struct.pack_into(buf, self.start, *flat)
        return ctypes.addressof(buf)

    def writer(self, indices: Sequence[int]) -> Callable[[Any, Sequence[Any]], None]:
        """A function writing new values of the by-value parameters ``indices`` (scalars,
        vectors, matrices, handles; ascending) into a buffer ``pack_into`` filled, in
        place: ``write(buf, values)``, one value per index (``param_writer.make_writer``).
        Made once per set of indices (every patchable launch of the kernel asks)."""
        return self._writers.get(indices)

    def _make_writer(self, indices: Sequence[int]) -> Callable[[Any, Sequence[Any]], None]:
        if not self.supported:
            raise TypeError("a signature with struct parameters is packed by Packed")
        fields: list = [None] * len(self.types)
        flatten: list = [None] * len(self.types)
        for i in indices:
            kind = self._kinds[i]
            if kind == "array":
                raise TypeError(f"parameter {i} is an array, not a by-value parameter")
            size, code, _ = _layout(self.types[i])
            fields[i] = (code, size)
            if kind == "handle":
                flatten[i] = _flatten_handle
            elif kind == "vector":
                flatten[i] = _flatten_composite
        return make_writer(indices, self.offsets, fields, flatten)


def _flatten_handle(v: Any, out: list) -> None:
    """A handle's one field."""
    out.append(int(v))


def _flatten_composite(v: Any, out: list) -> None:
    """A vector's or matrix's fields, row-major."""
    out.extend(np.asarray(v).reshape(-1).tolist())


def _align(n: int, to: int = 16) -> int:
    return (n + to - 1) // to * to


def _layout(t: T.Type) -> tuple[int, str, str]:
    """(size in bytes, struct code, kind) of one argument's bytes."""
    if isinstance(t, T.ArrayType):
        n = 1 + 2 * t.ndim
        return 8 * n, "q" * n, "array"
    if isinstance(t, T.HandleType):
        return 8, "Q", "handle"
    et = T.elem_type(t)
    code = et.struct
    n = 1 if isinstance(t, T.ScalarType) else _component_count(t)
    size = n * et.np_dtype.itemsize
    return size, code * n, "scalar" if n == 1 and isinstance(t, T.ScalarType) else "vector"


def _component_count(t: T.Type) -> int:
    n = 1
    for d in T.value_shape(t):
        n *= d
    return n
