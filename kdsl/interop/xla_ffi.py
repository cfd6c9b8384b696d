"""The part of XLA's FFI C API (``xla/ffi/api/c_api.h``) that kdsl's JAX handlers use.

XLA calls a registered handler with one ``XLA_FFI_CallFrame*``: the input buffers
(``args``), the output buffers (``rets``), the attributes of the call (``attrs``),
the execution context (for the CUDA stream) and a table of API functions (``api``,
used here to create errors and get the stream). Before the first call XLA may also
call the handler with a metadata extension in ``extension_start``, asking which API
version it was built for and its traits (command-buffer/CUDA-graph compatible).
The layouts below mirror the header field by field; only the names kdsl reads are
spelled out, and function pointers it never calls are ``c_void_p``.
"""

from __future__ import annotations

import ctypes
from typing import Any

import numpy as np

from kdsl.interop.dtypes import InteropTypeError
from kdsl.ir import types as T

c_size_t, c_int, c_int64, c_void_p = ctypes.c_size_t, ctypes.c_int, ctypes.c_int64, ctypes.c_void_p

API_MAJOR, API_MINOR = 0, 3  # the header version kdsl's layouts follow
EXTENSION_METADATA = 1
STAGE_EXECUTE = 3
ERROR_INTERNAL = 13
TRAIT_COMMAND_BUFFER_COMPATIBLE = 1
ATTR_ARRAY, ATTR_DICTIONARY, ATTR_SCALAR, ATTR_STRING = 1, 2, 3, 4

# XLA_FFI_DataType -> NumPy dtype, from the scalar table; XLA types kdsl lacks (bf16, fp8,
# complex...) are absent.
_NP_OF_XLA = {t.xla_ffi: t.np_dtype for t in T.SCALARS.values()}
_XLA_NAMES = {15: "complex64", 16: "bfloat16", 18: "complex128"}


def numpy_dtype(code: int) -> np.dtype:
    """The NumPy dtype of an ``XLA_FFI_DataType`` code (an ``InteropTypeError`` if none)."""
    try:
        return _NP_OF_XLA[code]
    except KeyError:
        name = _XLA_NAMES.get(code, f"XLA data type {code}")
        raise InteropTypeError(f"{name} has no kdsl equivalent") from None


class ExtensionBase(ctypes.Structure):
    """``XLA_FFI_Extension_Base``: a linked list of optional extensions."""


ExtensionBase._fields_ = [
    ("struct_size", c_size_t), ("type", c_int), ("next", ctypes.POINTER(ExtensionBase)),
]  # fmt: skip

# The fields every versioned struct of the API starts with (its size, then its extensions).
_HEADER = [("struct_size", c_size_t), ("extension_start", ctypes.POINTER(ExtensionBase))]


def _sized(struct: type[ctypes.Structure], *fields: Any) -> Any:
    """An argument struct for an API call: its size, no extensions, then ``fields``."""
    return struct(ctypes.sizeof(struct), None, *fields)


class ApiVersion(ctypes.Structure):
    """``XLA_FFI_Api_Version``."""

    _fields_ = [*_HEADER, ("major_version", c_int), ("minor_version", c_int)]


class Metadata(ctypes.Structure):
    """``XLA_FFI_Metadata``: what a handler tells XLA about itself."""

    _fields_ = [
        ("struct_size", c_size_t), ("api_version", ApiVersion), ("traits", ctypes.c_uint32),
        ("state_type_id", c_int64),
    ]  # fmt: skip


class MetadataExtension(ctypes.Structure):
    """``XLA_FFI_Metadata_Extension``."""

    _fields_ = [("extension_base", ExtensionBase), ("metadata", ctypes.POINTER(Metadata))]


class Buffer(ctypes.Structure):
    """``XLA_FFI_Buffer``: one input or output array (dense, row-major)."""

    _fields_ = [
        *_HEADER, ("dtype", c_int), ("data", c_void_p), ("rank", c_int64),
        ("dims", ctypes.POINTER(c_int64)),
    ]  # fmt: skip


class ByteSpan(ctypes.Structure):
    """``XLA_FFI_ByteSpan``: a string that is not NUL-terminated."""

    _fields_ = [("ptr", ctypes.POINTER(ctypes.c_char)), ("len", c_size_t)]


class Scalar(ctypes.Structure):
    """``XLA_FFI_Scalar``: a scalar attribute."""

    _fields_ = [("dtype", c_int), ("value", c_void_p)]


class AttrArray(ctypes.Structure):
    """``XLA_FFI_Array``: an array attribute."""

    _fields_ = [("dtype", c_int), ("size", c_size_t), ("data", c_void_p)]


class Args(ctypes.Structure):
    """``XLA_FFI_Args`` (and, with the same layout, ``XLA_FFI_Rets``)."""

    _fields_ = [
        *_HEADER, ("size", c_int64), ("types", ctypes.POINTER(c_int)),
        ("args", ctypes.POINTER(c_void_p)),
    ]  # fmt: skip


class Attrs(ctypes.Structure):
    """``XLA_FFI_Attrs``."""

    _fields_ = [
        *_HEADER, ("size", c_int64), ("types", ctypes.POINTER(c_int)),
        ("names", ctypes.POINTER(ctypes.POINTER(ByteSpan))), ("attrs", ctypes.POINTER(c_void_p)),
    ]  # fmt: skip


class ErrorCreateArgs(ctypes.Structure):
    """``XLA_FFI_Error_Create_Args``."""

    _fields_ = [*_HEADER, ("message", ctypes.c_char_p), ("errc", c_int)]


class StreamGetArgs(ctypes.Structure):
    """``XLA_FFI_Stream_Get_Args``."""

    _fields_ = [*_HEADER, ("ctx", c_void_p), ("stream", c_void_p)]


class DeviceOrdinalGetArgs(ctypes.Structure):
    """``XLA_FFI_DeviceOrdinal_Get_Args``."""

    _fields_ = [*_HEADER, ("ctx", c_void_p), ("device_ordinal", ctypes.c_int32)]


ErrorCreate = ctypes.CFUNCTYPE(c_void_p, ctypes.POINTER(ErrorCreateArgs))
StreamGet = ctypes.CFUNCTYPE(c_void_p, ctypes.POINTER(StreamGetArgs))
DeviceOrdinalGet = ctypes.CFUNCTYPE(c_void_p, ctypes.POINTER(DeviceOrdinalGetArgs))


_UNUSED = (
    "Type_Register", "ExecutionContext_Get", "State_Set", "State_Get", "DeviceMemory_Allocate",
    "DeviceMemory_Free", "ThreadPool_Schedule", "ThreadPool_NumThreads", "Future_Create",
    "Future_SetAvailable", "Future_SetError", "RunId_Get",
)  # fmt: skip


class Api(ctypes.Structure):
    """``XLA_FFI_Api``: the function table; the entries kdsl calls are typed."""

    _fields_ = [
        *_HEADER, ("api_version", ApiVersion), ("internal_api", c_void_p),
        ("XLA_FFI_Error_Create", ErrorCreate), ("XLA_FFI_Error_GetMessage", c_void_p),
        ("XLA_FFI_Error_Destroy", c_void_p), ("XLA_FFI_Handler_Register", c_void_p),
        ("XLA_FFI_Stream_Get", StreamGet),
        *((f"XLA_FFI_{name}", c_void_p) for name in _UNUSED),
        ("XLA_FFI_DeviceOrdinal_Get", DeviceOrdinalGet),
    ]  # fmt: skip


class CallFrame(ctypes.Structure):
    """``XLA_FFI_CallFrame``: everything one handler call gets."""

    _fields_ = [
        *_HEADER, ("api", ctypes.POINTER(Api)), ("ctx", c_void_p), ("stage", c_int),
        ("args", Args), ("rets", Args), ("attrs", Attrs), ("future", c_void_p),
    ]  # fmt: skip


Handler = ctypes.CFUNCTYPE(c_void_p, ctypes.POINTER(CallFrame))


def answer_metadata(frame: Any, traits: int) -> bool:
    """Fill in the metadata XLA asks for, if this call is that query (then return True)."""
    ext = frame.extension_start
    if not ext or ext.contents.type != EXTENSION_METADATA:
        return False
    meta = ctypes.cast(ext, ctypes.POINTER(MetadataExtension)).contents.metadata.contents
    meta.api_version.major_version = API_MAJOR
    meta.api_version.minor_version = API_MINOR
    meta.traits = traits
    return True


def buffers(table: Args) -> list[Buffer]:
    """The buffers of ``frame.args`` or ``frame.rets`` (all are buffers in this API)."""
    return [ctypes.cast(table.args[i], ctypes.POINTER(Buffer)).contents for i in range(table.size)]


def buffer_layouts(table: Args) -> tuple:
    """Each buffer's ``(data, dtype code, dims)``: all a view of it depends on, as a key."""
    return tuple(
        (b.data, b.dtype, tuple(b.dims[: b.rank]))
        for b in map(Buffer.from_address, table.args[: table.size])
    )


def int_attribute(attrs: Attrs, name: bytes) -> int | None:
    """The integer scalar attribute ``name`` of a call, read without decoding the others."""
    for i in range(attrs.size):
        span = attrs.names[i].contents
        if attrs.types[i] == ATTR_SCALAR and ctypes.string_at(span.ptr, span.len) == name:
            return int(_scalar_value(attrs.attrs[i]))
    return None


def buffer_shape(buf: Buffer) -> tuple[int, ...]:
    """The dims of an ``XLA_FFI_Buffer``."""
    return tuple(buf.dims[i] for i in range(buf.rank))


def _scalar_value(ptr: int) -> Any:
    s = ctypes.cast(ptr, ctypes.POINTER(Scalar)).contents
    dt = numpy_dtype(s.dtype)
    return np.frombuffer(ctypes.string_at(s.value, dt.itemsize), dt)[0].item()


def _array_value(ptr: int) -> np.ndarray:
    a = ctypes.cast(ptr, ctypes.POINTER(AttrArray)).contents
    dt = numpy_dtype(a.dtype)
    return np.frombuffer(ctypes.string_at(a.data, dt.itemsize * a.size), dt).copy()


def _string_value(ptr: int) -> str:
    span = ctypes.cast(ptr, ctypes.POINTER(ByteSpan)).contents
    return ctypes.string_at(span.ptr, span.len).decode()


def _dict_value(ptr: int) -> dict[str, Any]:
    return attributes(ctypes.cast(ptr, ctypes.POINTER(Attrs)).contents)


_ATTR_READERS = {
    ATTR_SCALAR: _scalar_value, ATTR_ARRAY: _array_value, ATTR_STRING: _string_value,
    ATTR_DICTIONARY: _dict_value,
}  # fmt: skip


def attributes(attrs: Attrs) -> dict[str, Any]:
    """The attributes of a call as a dict of Python scalars, arrays, strings and dicts."""
    out = {}
    for i in range(attrs.size):
        span = attrs.names[i].contents
        name = ctypes.string_at(span.ptr, span.len).decode()
        out[name] = _ATTR_READERS[attrs.types[i]](attrs.attrs[i])
    return out


def stream_of(frame: Any) -> int:
    """The CUDA stream (``cudaStream_t`` as an int) of a GPU call."""
    args = _sized(StreamGetArgs, frame.ctx, None)
    err = frame.api.contents.XLA_FFI_Stream_Get(ctypes.byref(args))
    if err:
        raise RuntimeError("XLA_FFI_Stream_Get failed")
    return args.stream or 0


def device_ordinal(frame: Any) -> int | None:
    """The GPU ordinal of a call, or None when XLA's API table is too old to say."""
    api = frame.api.contents
    if api.struct_size < ctypes.sizeof(Api):
        return None
    args = _sized(DeviceOrdinalGetArgs, frame.ctx, 0)
    if api.XLA_FFI_DeviceOrdinal_Get(ctypes.byref(args)):
        return None
    return int(args.device_ordinal)


def make_error(frame: Any, message: str) -> int:
    """An ``XLA_FFI_Error*`` carrying ``message`` (XLA takes ownership and raises it)."""
    args = _sized(ErrorCreateArgs, message.encode(), ERROR_INTERNAL)
    return frame.api.contents.XLA_FFI_Error_Create(ctypes.byref(args))
