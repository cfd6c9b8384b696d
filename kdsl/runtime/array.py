"""``kdsl.array``: a typed, strided array on one device.

Its buffer ``_buf`` is a NumPy array on the CPU and a ``cupy.ndarray`` on a CUDA
device (see ``cuda_memory``); it holds the element shape after the array's own
dims: a ``vec3`` array of shape ``(n,)`` wraps an ``(n, 3)`` float32 buffer.
CuPy work on a CUDA array runs on its device's current kdsl stream; methods that
bring data to the host (``numpy``, ``list``, one element, ``repr``) wait for it.
``array(dtype=X, ndim=k)`` with no data and no shape is also how kernels annotate
array parameters; every array exposes ``__kdsl_type__`` (``ArrayType(dtype, ndim)``)
for the frontend.
"""

from __future__ import annotations

import builtins
from typing import Any

import numpy as np

from kdsl.errors import KdslError
from kdsl.ir import types as T
from kdsl.runtime import cuda_memory as mem
from kdsl.runtime.adapters import adapter
from kdsl.runtime.annotation import ArrayAnnotation, subscript
from kdsl.runtime.device import Device, get_device
from kdsl.runtime.dtypes import (
    host_value,
    inner_shape,
    normalize_shape,
    np_dtype,
    public_dtype,
    resolve_dtype,
    scalar_dtype_of_numpy,
)


def _is_any(dtype: Any) -> bool:
    return dtype is Any or dtype is None


class array:
    """A typed, strided array (see the module docstring)."""

    def __class_getitem__(cls, params: Any) -> ArrayAnnotation:
        """``array[dtype]`` or ``array[dtype, ndim]``: the annotation Warp 1.19 writes."""
        return subscript(array, params, cls.__dict__.get("_fixed_ndim"))

    @staticmethod
    def annotation_type(dtype: Any, ndim: int) -> T.ArrayType:
        """The kernel type of an ``ndim``-d array of ``dtype`` (for ``ArrayAnnotation``)."""
        return T.ArrayType(resolve_dtype(dtype), ndim)

    def __init__(
        self,
        data: Any = None,
        dtype: Any = Any,
        shape: Any = None,
        device: Any = None,
        requires_grad: bool = False,
        copy: bool = True,
        ndim: int | None = None,
        length: int | None = None,
        # Warp's allocation hints; CuPy's pool and NumPy decide these, accepted so
        # Warp code ports. Unknown keywords still raise TypeError.
        pinned: bool = False,
        owner: bool = False,
        deleter: Any = None,
    ) -> None:
        t = None if _is_any(dtype) else resolve_dtype(dtype)
        if isinstance(data, array):
            t = data._t if t is None else t
            data, src_dev = data._buf, data._device
        elif mem.is_cuda_buffer(data):
            data, src_dev = mem.wrap_cuda(data)
        else:
            src_dev = get_device("cpu")
        # Data already on a GPU stays there unless a device is named.
        dev = get_device(device if device is not None or src_dev.is_cpu else src_dev)
        dims = shape if shape is not None else length
        if data is None:
            buf, t = _alloc(t, dims, ndim, dev)
        elif src_dev == dev:
            with mem.scope(dev):
                buf, t = _from_data(mem.xp(dev), data, t, dims, ndim, copy)
        elif dev.is_cpu or src_dev.is_cpu:
            # Check and convert on the host, where errors are cheap, then move once.
            host = mem.to_host(data, src_dev) if src_dev.is_cuda else data
            buf, t = _from_data(np, host, t, dims, ndim, copy=False)
            if dev.is_cuda:
                buf = mem.from_host(buf, dev)
        else:  # GPU to GPU: copy over, then convert there
            moved = mem.transfer(data, src_dev, dev)
            with mem.scope(dev):
                buf, t = _from_data(mem.xp(dev), moved, t, dims, ndim, copy=False)
        self._init(buf, t, dev, requires_grad)

    def _init(self, buf: Any, t: T.Type | None, dev: Device, requires_grad: bool) -> None:
        self._buf = buf
        self._t = t
        self._inner = inner_shape(t) if t is not None else ()
        self._ndim = buf.ndim - len(self._inner)
        self._device = dev
        self._grad: array | None = None
        #: Keep ``.grad`` when a backward pass goes through a store into this array
        #: (by default the store consumes it, as in Warp; see docs/autodiff.md).
        self.retain_grad = False
        self.requires_grad = requires_grad

    @classmethod
    def _wrap(cls, buf: Any, t: T.Type, device: Device, requires_grad: bool = False) -> array:
        """An array over ``buf`` without copying (views, constructors)."""
        out = array.__new__(array)
        out._init(buf, t, device, requires_grad)
        return out

    # --- type ----------------------------------------------------------------
    @property
    def __kdsl_type__(self) -> T.ArrayType:
        if self._t is None:
            raise TypeError("array(dtype=Any) is generic: kernels need a concrete dtype")
        return T.ArrayType(self._t, self._ndim)

    @property
    def dtype(self) -> Any:
        """The element type: ``kdsl.float32``, ``kdsl.vec3``... (Any when generic)."""
        return Any if self._t is None else public_dtype(self._t)

    @property
    def shape(self) -> tuple[int, ...]:
        return self._buf.shape[: self._ndim]

    @property
    def ndim(self) -> int:
        return self._ndim

    @property
    def size(self) -> int:
        return int(np.prod(self.shape, dtype=np.int64))

    @property
    def strides(self) -> tuple[int, ...]:
        """Byte strides of the array's dims (not of the element's components)."""
        return self._buf.strides[: self._ndim]

    @property
    def device(self) -> Device:
        return self._device

    @property
    def ptr(self) -> int:
        """Address of the first element (a device address for CUDA arrays)."""
        if self._device.is_cuda:
            return int(self._buf.data.ptr)
        return int(self._buf.__array_interface__["data"][0])

    @property
    def is_contiguous(self) -> bool:
        return bool(self._buf.flags.c_contiguous)

    @property
    def requires_grad(self) -> bool:
        return self._requires_grad

    @requires_grad.setter
    def requires_grad(self, value: bool) -> None:
        self._requires_grad = builtins.bool(value)
        if self._requires_grad and self._grad is None and self._t is not None:
            self._grad = array._wrap(mem.zeros_like(self._buf, self._device), self._t, self._device)

    @property
    def grad(self) -> array | None:
        """The gradient array (allocated when ``requires_grad`` is set)."""
        return self._grad

    @grad.setter
    def grad(self, value: array | None) -> None:
        self._grad = value

    # --- data ----------------------------------------------------------------
    def numpy(self) -> np.ndarray:
        """The data as NumPy (element dims appended for vector dtypes).

        Zero-copy on the CPU. For a CUDA array, a host copy made after the work
        enqueued on the device's stream has finished (so no ``synchronize()`` is needed).
        """
        if self._device.is_cuda:
            return mem.to_host(self._buf, self._device)
        return self._buf.view()

    @property
    def __array_interface__(self) -> dict:
        if self._device.is_cuda:  # so NumPy never mistakes device memory for host memory
            raise AttributeError("a CUDA array has no __array_interface__; use .numpy()")
        return self._buf.__array_interface__

    @property
    def __cuda_array_interface__(self) -> dict:
        """Version 3 of the CUDA array interface; ``stream`` is the device's kdsl stream."""
        if not self._device.is_cuda:
            raise AttributeError("a CPU array has no __cuda_array_interface__")
        from kdsl.runtime.stream import get_stream

        face = dict(self._buf.__cuda_array_interface__)
        face["version"] = 3
        # Consumers wait on this stream before touching the data (0 is reserved).
        face["stream"] = get_stream(self._device).cuda_stream or 1
        return face

    def __dlpack__(
        self,
        *,
        stream: Any = None,
        max_version: tuple[int, int] | None = None,
        dl_device: tuple[int, int] | None = None,
        copy: builtins.bool | None = None,
    ) -> Any:
        """DLPack export, by the buffer's own (NumPy's or CuPy's) ``__dlpack__``.

        Versioned (1.0) when ``max_version`` allows it, legacy otherwise; element
        dims are appended (a ``vec3`` array exports an ``(n, 3)`` tensor). On a GPU
        the consumer's ``stream`` is made to wait for this device's kdsl stream.
        """
        export = adapter("dlpack_export")
        if export is None:
            raise KdslError("DLPack export needs kdsl.interop (import kdsl)")
        return export(
            self._buf, self._device, stream=stream, max_version=max_version,
            dl_device=dl_device, copy=copy,
        )  # fmt: skip

    def __dlpack_device__(self) -> tuple[int, int]:
        """``(1, 0)`` on the CPU, ``(2, ordinal)`` on a CUDA device (DLPack device codes)."""
        kind, index = self._buf.__dlpack_device__()
        return int(kind), int(index)

    def list(self) -> list:
        """The elements as a flat Python list (vector classes for vector dtypes)."""
        flat = np.ascontiguousarray(self.numpy()).reshape(-1, *self._inner)
        if isinstance(self._t, T.StructType):
            return [self.dtype.from_numpy(x) for x in flat]
        if not self._inner:
            return list(flat)
        cls = self.dtype
        return [cls(x) for x in flat]

    def _device_value(self, value: Any) -> Any:
        # A fill/setitem value checked on the host, then placed on this array's device
        # (inside mem.scope, so the upload is on the device's stream).
        host = np.asarray(host_value(self._t, value), dtype=self._buf.dtype)
        return mem.cupy().asarray(host) if self._device.is_cuda else host

    def fill_(self, value: Any) -> array:
        """Set every element to ``value`` (a scalar, or a vector for vector dtypes)."""
        if self._device.is_cuda and isinstance(self._t, T.StructType):
            return self._update_records(..., value)
        try:
            with mem.scope(self._device):
                self._buf[...] = self._device_value(value)
        except ValueError as e:
            raise KdslError(f"cannot fill an array of {self._t} with {value!r}: {e}") from None
        return self

    fill = fill_

    def zero_(self) -> array:
        """Set every element to zero."""
        with mem.scope(self._device):
            if self._device.is_cuda and isinstance(self._t, T.StructType):
                self._buf.data.memset_async(0, self._buf.nbytes)  # CuPy cannot fill records
            else:
                self._buf.fill(0)
        return self

    def assign(self, src: Any) -> array:
        """Copy ``src`` (an array on any device, a NumPy/CuPy array or a list) into this one."""
        if isinstance(src, array):
            data = src._buf if src._device == self._device else src.to(self._device)._buf
        elif mem.is_cuda_buffer(src):
            data, where = mem.wrap_cuda(src)
            if where != self._device:
                data = mem.transfer(data, where, self._device)
        else:
            data = src if isinstance(src, np.ndarray) else np.asarray(src, dtype=self._buf.dtype)
            if self._device.is_cuda:
                with mem.scope(self._device):
                    data = mem.cupy().asarray(np.ascontiguousarray(data))
        xp = mem.xp(self._device)
        with mem.scope(self._device):
            if data.size == self._buf.size and data.shape != self._buf.shape:
                data = data.reshape(self._buf.shape)
            try:
                xp.copyto(self._buf, data, casting="unsafe")
            except ValueError as e:
                raise KdslError(
                    f"cannot assign a {data.shape} array to a {self.shape} array: {e}"
                ) from None
        if isinstance(src, array):  # differentiable on an active Tape, like kdsl.copy
            from kdsl.runtime.tape import record_copy

            record_copy(self, src, 0, 0, self.size)
        return self

    def to(self, device: Any) -> array:
        """This array on ``device`` (itself when it already lives there)."""
        dev = get_device(device)
        if dev == self._device:
            return self
        buf = mem.transfer(self._buf, self._device, dev)
        return array._wrap(buf, self._t, dev, self._requires_grad)

    def copy(self) -> array:
        """A new contiguous array on the same device with a copy of the data."""
        with mem.scope(self._device):
            buf = mem.xp(self._device).array(self._buf, copy=True, order="C")
        return array._wrap(buf, self._t, self._device, self._requires_grad)

    def reshape(self, shape: Any) -> array:
        """A view (or copy, when strides forbid a view) with a new shape."""
        dims = normalize_shape(shape)
        if -1 not in dims and int(np.prod(dims)) != self.size:
            raise KdslError(f"cannot reshape an array of shape {self.shape} to {dims}")
        with mem.scope(self._device):
            buf = self._buf.reshape(dims + self._inner)
        return array._wrap(buf, self._t, self._device)

    def flatten(self) -> array:
        """A 1-d view (or copy) of the elements."""
        return self.reshape((self.size,))

    # --- indexing ------------------------------------------------------------
    def _key(self, key: Any) -> tuple:
        key = key if isinstance(key, tuple) else (key,)
        for k in key:
            ok = (
                isinstance(k, slice)
                or k is Ellipsis
                or (isinstance(k, builtins.int | np.integer) and not isinstance(k, builtins.bool))
            )
            if not ok:
                raise TypeError(f"a kdsl array is indexed by integers and slices, not {k!r}")
        real = [k for k in key if k is not Ellipsis]
        if len(real) > self._ndim:
            raise IndexError(f"too many indices for a {self._ndim}-d array: {len(real)}")
        if any(k is Ellipsis for k in key):
            i = next(i for i, k in enumerate(key) if k is Ellipsis)
            fill = (slice(None),) * (self._ndim - len(real))
            key = key[:i] + fill + tuple(k for k in key[i + 1 :] if k is not Ellipsis)
        return key

    def __getitem__(self, key: Any) -> Any:
        view = self._buf[self._key(key)]
        if view.ndim == len(self._inner):  # one element
            if self._device.is_cuda:
                view = mem.to_host(view, self._device)  # waits for the stream
            if isinstance(self._t, T.StructType):
                return self.dtype.from_numpy(view[()])
            if not self._inner:
                return view[()]
            return self.dtype(view)
        return array._wrap(view, self._t, self._device)

    def _update_records(self, key: Any, value: Any) -> array:
        # CuPy copies structured buffers but cannot assign into them: update on the host.
        host = mem.to_host(self._buf, self._device)
        host[key] = np.asarray(host_value(self._t, value), dtype=host.dtype)
        with mem.scope(self._device):
            self._buf.set(host)
        return self

    def __setitem__(self, key: Any, value: Any) -> None:
        if self._device.is_cuda and isinstance(self._t, T.StructType):
            self._update_records(self._key(key), value)
            return
        with mem.scope(self._device):
            self._buf[self._key(key)] = self._device_value(value)

    def __len__(self) -> int:
        return self._buf.shape[0]

    def __repr__(self) -> str:
        name = getattr(self.dtype, "__name__", str(self.dtype))
        body = np.array2string(self.numpy(), separator=", ", prefix="array(")
        return f"array({body}, dtype={name}, device='{self._device}')"

    def __str__(self) -> str:
        return str(self.numpy())


def _subclass(ndim: int) -> type:
    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs["ndim"] = ndim
        array.__init__(self, *args, **kwargs)

    doc = (f"A {ndim}-d ``array``: ``array{ndim}d[float]`` (or ``array{ndim}d(dtype=float)``) "
           "annotates a kernel parameter.")
    return type(f"array{ndim}d", (array,),
                {"__init__": __init__, "__doc__": doc, "_fixed_ndim": ndim})  # fmt: skip


array1d, array2d, array3d, array4d = (_subclass(n) for n in (1, 2, 3, 4))


def _alloc(
    t: T.Type | None, shape: Any, ndim: int | None, dev: Device
) -> tuple[Any, T.Type | None]:
    if shape is None:  # an annotation, or an empty array
        dims = (0,) * (ndim or 1)
    else:
        dims = normalize_shape(shape)
        if ndim is not None and len(dims) != ndim:
            raise KdslError(f"shape {dims} has {len(dims)} dimensions but ndim={ndim}")
    if t is None:
        full, dtype = dims, np.dtype(np.float32)
    else:
        full, dtype = dims + inner_shape(t), np_dtype(t)
    if dev.is_cuda and isinstance(t, T.StructType):  # CuPy cannot fill structured buffers
        return mem.from_host(np.zeros(full, dtype), dev), t
    buf = mem.empty(full, dtype, dev)
    with mem.scope(dev):
        buf.fill(0)
    return buf, t


def _from_data(
    xp: Any, data: Any, t: T.Type | None, shape: Any, ndim: int | None, copy: bool
) -> tuple[Any, T.Type]:
    """``data`` as a buffer of ``xp`` (NumPy or CuPy, on the current device), checked."""
    want = np_dtype(t) if t is not None else None
    data = host_value(t, data) if t is not None else data
    try:
        buf = xp.array(data, dtype=want, copy=True) if copy else xp.asarray(data, dtype=want)
    except (TypeError, ValueError) as e:
        raise KdslError(
            f"cannot make an array of {t or 'inferred dtype'} from the data: {e}"
        ) from None
    if t is None:
        t = scalar_dtype_of_numpy(buf.dtype)
    inner = inner_shape(t)
    if shape is not None:
        dims = normalize_shape(shape)
        if int(np.prod(dims + inner)) != buf.size:
            raise KdslError(f"data of {buf.size} values does not fill shape {dims} of {t}")
        buf = buf.reshape(dims + inner)
    elif inner and buf.shape[buf.ndim - len(inner) :] != inner:
        raise KdslError(
            f"data of shape {buf.shape} cannot hold {t} elements: its last dims must be {inner}"
        )
    outer = buf.ndim - len(inner)
    if ndim is not None and outer != ndim:
        raise KdslError(f"data has {outer} dimensions but ndim={ndim}")
    if not 1 <= outer <= 4:
        raise KdslError(f"arrays have 1 to 4 dimensions; the data gives {outer}")
    return buf, t
