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
import math
from typing import Any

import numpy as np

from kdsl.errors import KdslError
from kdsl.ir import types as T
from kdsl.runtime import cuda_memory as mem
from kdsl.runtime.adapters import adapter
from kdsl.runtime.annotation import ArrayAnnotation, subscript
from kdsl.runtime.device import Device, get_device
from kdsl.runtime.dtypes import (
    host_scalar,
    host_value,
    host_view,
    inner_shape,
    normalize_shape,
    np_dtype,
    public_dtype,
    resolve_dtype,
    scalar_dtype_of_numpy,
)
from kdsl.runtime.graphs import state as graphs


def _is_any(dtype: Any) -> bool:
    return dtype is Any or dtype is None


class array:
    """A typed, strided array (see the module docstring)."""

    # Read mark and viewed array for ``config.verify_autograd_array_access``
    # (``kdsl/runtime/array_access.py``); set only when that setting or a view needs them.
    _is_read = False
    _viewed: array | None = None

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
        *,
        strides: Any = None,
        ptr: int | None = None,
        capacity: int | None = None,
        grad: array | None = None,
        retain_grad: bool = False,
    ) -> None:
        t = None if _is_any(dtype) else resolve_dtype(dtype)
        if ptr is not None or strides is not None:
            if ptr is None or data is not None:
                raise KdslError("array(): strides= goes with ptr= (and no data)")
            if t is None or shape is None:
                raise KdslError("array(ptr=...) needs a dtype and a shape")
            dev = get_device(device)
            buf = _from_ptr(builtins.int(ptr), t, normalize_shape(shape), strides, capacity, dev)
            self._init(buf, t, dev, requires_grad)
        else:
            self._init_data(data, t, shape, device, requires_grad, copy, ndim, length)
        if grad is not None:
            self.grad = grad
        self.retain_grad = builtins.bool(retain_grad)

    def _init_data(
        self, data: Any, t: T.Type | None, shape: Any, device: Any, requires_grad: bool,
        copy: bool, ndim: int | None, length: int | None,
    ) -> None:  # fmt: skip
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
        if isinstance(t, T.StructType) and t.align:
            self._check_alignment(t.align)
        self._grad: array | None = None
        #: Keep ``.grad`` when a backward pass goes through a store into this array
        #: (by default the store consumes it, as in Warp; see docs/autodiff.md).
        self.retain_grad = False
        #: Whether this is a transposed view (Warp's flag; the strides say the same).
        self.is_transposed = False
        self.requires_grad = requires_grad

    def _check_alignment(self, align: int) -> None:
        """Refuse an array of a struct declared ``align`` (``StructType``) whose address
        or strides are not multiples of it: kernels load its elements as aligned."""
        if self.size == 0:
            return
        bad = [s for s, d in zip(self.strides, self.shape) if d > 1 and s % align]
        if self.ptr % align or bad:
            raise KdslError(
                f"an array of {self._t.name} (declared align={align}) needs its address and "
                f"strides to be multiples of {align} bytes; got address {self.ptr:#x}, strides "
                f"{self.strides}"
            )

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
    def __kdsl_generic__(self) -> tuple | None:
        """``array(dtype=Any)`` annotates a generic parameter (see ``frontend.generic``)."""
        if self._t is not None:
            return None
        return (lambda dtype: T.ArrayType(dtype, self._ndim)), self._ndim

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
        return math.prod(self.shape)  # (Python ints: several times cheaper than np.prod)

    @property
    def strides(self) -> tuple[int, ...]:
        """Byte strides of the array's dims (not of the element's components)."""
        return self._buf.strides[: self._ndim]

    @property
    def device(self) -> Device:
        return self._device

    def ipc_handle(self) -> bytes:
        """The CUDA IPC handle of this array's allocation, for ``from_ipc_handle`` in
        another process (see ``kdsl.runtime.ipc`` for which arrays qualify)."""
        from kdsl.runtime.ipc import array_ipc_handle  # ipc builds arrays: imported late

        return array_ipc_handle(self)

    @property
    def ptr(self) -> int:
        """Address of the first element (a device address for CUDA arrays)."""
        if self._device.is_cuda:
            return int(self._buf.data.ptr)
        return int(self._buf.__array_interface__["data"][0])

    @property
    def is_contiguous(self) -> bool:
        return bool(self._buf.flags.c_contiguous)

    def memory_span(self) -> tuple[int, int] | None:
        """(address, bytes) of the array's memory when it is one contiguous span, else
        None (a strided view)."""
        if not self._buf.flags.c_contiguous:
            return None
        return self.ptr, int(self._buf.nbytes)

    @property
    def requires_grad(self) -> bool:
        return self._requires_grad

    @requires_grad.setter
    def requires_grad(self, value: bool) -> None:
        if value and self._t is T.BF16:
            raise KdslError("bfloat16 arrays carry no gradients in kdsl (a storage type); "
                            "differentiate through a float32 copy")  # fmt: skip
        self._requires_grad = builtins.bool(value)
        if self._requires_grad and self._grad is None and self._t is not None:
            self._grad = array._wrap(mem.zeros_like(self._buf, self._device), self._t, self._device)

    @property
    def grad(self) -> array | None:
        """The gradient array (allocated when ``requires_grad`` is set)."""
        return self._grad

    @grad.setter
    def grad(self, value: array | None) -> None:
        """Set the gradient array: None drops it (``requires_grad`` becomes False); an
        array must match this one's dtype, shape, strides and device (Warp's rule)."""
        if value is None:
            self._grad, self._requires_grad = None, False
            return
        if not isinstance(value, array):
            raise KdslError(f"array.grad must be a kdsl array or None, not {type(value).__name__}")
        for what, want, got in (
            ("dtype", self._t, value._t),
            ("shape", self.shape, value.shape),
            ("strides", self.strides, value.strides),
            ("device", self._device, value._device),
        ):
            if want != got:
                raise KdslError(f"the gradient array has {what} {got}, this array has {want}")
        self._grad, self._requires_grad = value, True

    # --- data ----------------------------------------------------------------
    def numpy(self) -> np.ndarray:
        """The data as NumPy (element dims appended for vector dtypes).

        Zero-copy on the CPU. For a CUDA array, a host copy made after the work
        enqueued on the device's stream has finished (so no ``synchronize()`` is needed).
        """
        if self._device.is_cuda:
            return host_view(self._t, mem.to_host(self._buf, self._device))
        if graphs.ACTIVE:  # captured CPU work has not run: refuse, as on CUDA
            graphs.refuse_host_read(self._device, "numpy()")
        return host_view(self._t, self._buf.view())

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
            return host_scalar(self._t, flat).tolist()  # Python numbers, as Warp's
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
                if graphs.ACTIVE:  # recorded on the CPU, a fill kernel on CUDA
                    host = np.asarray(host_value(self._t, value), dtype=self._buf.dtype)
                    graphs.captured_fill(self._buf, self._device, host)
                    return self
                self._buf[...] = self._device_value(value)
        except ValueError as e:
            raise KdslError(f"cannot fill an array of {self._t} with {value!r}: {e}") from None
        return self

    fill = fill_

    def zero_(self) -> array:
        """Set every element to zero."""
        if graphs.ACTIVE and self._device.is_cpu:
            graphs.captured_fill(self._buf, self._device, np.zeros((), self._buf.dtype))
            return self
        if self._device.is_cuda and not graphs.ACTIVE and self._buf.flags.c_contiguous:
            mem.zero_async(self._buf, self._device)  # records too (CuPy cannot fill those)
            return self
        with mem.scope(self._device):
            if self._device.is_cuda and isinstance(self._t, T.StructType):
                self._buf.data.memset_async(0, self._buf.nbytes)  # CuPy cannot fill records
            else:
                self._buf.fill(0)
        return self

    def assign(self, src: Any) -> array:
        """Copy ``src`` (an array on any device, a NumPy/CuPy array or a list) into this one."""
        if graphs.ACTIVE and self._device.is_cpu and graphs.record_assign(self, src):
            if isinstance(src, array):
                from kdsl.runtime.tape import record_copy

                record_copy(self, src, 0, 0, self.size)
            return self
        if isinstance(src, array):
            data = src._buf if src._device == self._device else src.to(self._device)._buf
        elif mem.is_cuda_buffer(src):
            data, where = mem.wrap_cuda(src)
            if self._t is T.BF16 and data.dtype != np.uint16:  # only bits copy as they are
                raise KdslError(f"cannot assign device data of {data.dtype} to a bfloat16 "
                                "array: pass uint16 bits, or host data to be rounded")  # fmt: skip
            if where != self._device:
                data = mem.transfer(data, where, self._device)
        else:
            src = host_value(self._t, src)  # struct instances, bfloat16 bits
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

    def to(self, device: Any, requires_grad: bool | None = None) -> array:
        """This array on ``device``: itself when it already lives there, else a contiguous
        copy (``kdsl.clone``, so differentiable on an active Tape)."""
        dev = get_device(device)
        if dev == self._device:
            return self
        from kdsl.runtime.alloc import clone

        return clone(self, device=dev, requires_grad=requires_grad)

    def contiguous(self) -> array:
        """This array when it is contiguous, else a contiguous copy (``kdsl.clone``)."""
        if self.is_contiguous:
            return self
        from kdsl.runtime.alloc import clone

        return clone(self)

    def copy(self) -> array:
        """A new contiguous array on the same device with a copy of the data."""
        with mem.scope(self._device):
            buf = mem.xp(self._device).array(self._buf, copy=True, order="C")
        return array._wrap(buf, self._t, self._device, self._requires_grad)

    def mark_init(self) -> None:
        """Clear the read mark ``config.verify_autograd_array_access`` keeps (Warp's)."""
        self._is_read = False

    def mark_read(self) -> None:
        """Mark this array, and the arrays it views, as read by a recorded launch."""
        a: array | None = self
        while a is not None:
            a._is_read = True
            a = a._viewed

    def mark_write(self, **site: Any) -> None:
        """Warn when this array, read by a recorded launch, is written: gradients of that
        launch would be wrong. ``site``: Warp's ``arg_name``, ``kernel_name``,
        ``operation``, ``filename``, ``lineno`` naming the writer."""
        if self._is_read:
            from kdsl.runtime.array_access import warn_write_after_read

            warn_write_after_read(self, site)

    def _view(self, buf: Any, t: T.Type, grad: array | None) -> array:
        # A view over ``buf`` whose gradient is ``grad`` (the same view of self.grad).
        out = array._wrap(buf, t, self._device)
        out._viewed = self
        if grad is not None:
            out._grad, out._requires_grad = grad, True
        out.retain_grad = self.retain_grad
        return out

    def reshape(self, shape: Any) -> array:
        """A view with a new shape (one dim may be -1); the array must be contiguous.

        As in Warp, a strided array (a transpose, a slice with steps) is refused:
        ``a.contiguous().reshape(...)`` copies first.
        """
        if not self.is_contiguous:
            raise KdslError(
                f"cannot reshape a non-contiguous array (shape {self.shape}, strides "
                f"{self.strides}) as a view; call .contiguous() first"
            )
        dims_t = _reshape_dims(shape, self.shape, self.size)
        with mem.scope(self._device):
            buf = self._buf.reshape(dims_t + self._inner)
        grad = None if self._grad is None else self._grad.reshape(dims_t)
        return self._view(buf, self._t, grad)

    def flatten(self) -> array:
        """A 1-d view of the elements (the array must be contiguous, as in Warp)."""
        if self._ndim == 1:
            return self
        if not self.is_contiguous:
            raise KdslError("cannot flatten a non-contiguous array as a view; call "
                            ".contiguous() first")  # fmt: skip
        return self.reshape((self.size,))

    def transpose(self, axes: Any = None) -> array:
        """A view with the dims permuted by ``axes`` (reversed when None); no copy.

        The result is strided (``is_contiguous`` False for a real permutation) and
        launches as it is on every backend.
        """
        if self._ndim == 1 and axes is None:
            return self
        order = tuple(range(self._ndim))[::-1] if axes is None else tuple(axes)
        if sorted(order) != list(range(self._ndim)) or not all(
            isinstance(a, builtins.int | np.integer) and not isinstance(a, builtins.bool)
            for a in order
        ):
            raise KdslError(
                f"transpose(): axes must be a permutation of 0..{self._ndim - 1}, got {axes!r}"
            )
        order = tuple(builtins.int(a) for a in order)
        full = order + tuple(range(self._ndim, self._buf.ndim))
        buf = self._buf.transpose(full)
        grad = None if self._grad is None else self._grad.transpose(order)
        out = self._view(buf, self._t, grad)
        out.is_transposed = self.is_transposed != (order != tuple(range(self._ndim)))
        return out

    def view(self, dtype: Any) -> array:
        """The same memory seen as ``dtype`` (no copy), with Warp's size rules.

        A dtype of the same byte size keeps the shape and strides (``int32`` as
        ``uint32``, ``vec4`` as ``quat``, ``vec4ub`` as ``uint32``); a vector or
        matrix seen as its scalar type gains its component dims (``vec3`` (n,) to
        float (n, 3)); scalars seen as a vector or matrix lose their trailing dims,
        which must match its shape and be contiguous.
        """
        t = resolve_dtype(dtype)
        if self._t is None:
            raise KdslError("view(): a generic array (dtype=Any) has no memory to view")
        src_size, dst_size = _type_bytes(self._t), _type_bytes(t)
        outer, outer_strides = self.shape, self.strides
        if src_size == dst_size:
            shape, strides = outer + inner_shape(t), outer_strides + _inner_strides(t)
        elif isinstance(t, T.ScalarType) and isinstance(self._t, T.VectorType | T.MatrixType):
            if _type_bytes(T.elem_type(self._t)) != dst_size:
                raise KdslError(
                    f"view(): cannot view {self._t} as {t}: its components have "
                    f"{_type_bytes(T.elem_type(self._t))} bytes, {t} has {dst_size}"
                )
            if self._ndim + len(self._inner) > 4:
                raise KdslError(f"view(): {self._t} as {t} would give more than 4 dimensions")
            shape, strides = self._buf.shape, self._buf.strides
        elif isinstance(self._t, T.ScalarType) and isinstance(t, T.VectorType | T.MatrixType):
            inner = inner_shape(t)
            if _type_bytes(T.elem_type(t)) != src_size:
                raise KdslError(
                    f"view(): cannot view {self._t} as {t}: its components have "
                    f"{_type_bytes(T.elem_type(t))} bytes, {self._t} has {src_size}"
                )
            k = len(inner)
            if self._ndim < k or outer[self._ndim - k :] != inner:
                raise KdslError(
                    f"view(): an array of shape {outer} cannot be viewed as {t}: its last "
                    f"dims must be {inner}"
                )
            if outer_strides[self._ndim - k :] != _inner_strides(t):
                raise KdslError(
                    f"view(): the last dims of an array with strides {outer_strides} are not "
                    f"contiguous, as {t} needs"
                )
            shape = (outer[: self._ndim - k] or (1,)) + inner
            strides = (outer_strides[: self._ndim - k] or (dst_size,)) + _inner_strides(t)
        else:
            raise KdslError(
                f"view(): cannot view {self._t} ({src_size} bytes) as {t} ({dst_size} bytes)"
            )
        buf = _restride(self._buf, self._device, np_dtype(t), shape, strides)
        grad = None if self._grad is None else self._grad.view(t)
        return self._view(buf, t, grad)

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
                return host_scalar(self._t, view[()])
            return self.dtype(view)
        grad = None if self._grad is None else self._grad[key]
        return self._view(view, self._t, grad)

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

    doc = (
        f"A {ndim}-d ``array``: ``array{ndim}d[float]`` (or ``array{ndim}d(dtype=float)``) "
        "annotates a kernel parameter."
    )
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
    if outer == 0 and inner:
        # One vector/matrix value (``wp.array(np.array(q), dtype=wp.quat)``): Warp makes
        # a one-element array of it.
        buf, outer = buf.reshape((1, *inner)), 1
    elif outer == 0:
        raise KdslError(
            f"array data must be a sequence or an array, not the scalar {data!r:.40}; "
            "write array([x]) for a one-element array"
        )
    if ndim is not None and outer != ndim:
        raise KdslError(f"data has {outer} dimensions but ndim={ndim}")
    if not 1 <= outer <= 4:
        raise KdslError(f"arrays have 1 to 4 dimensions; the data gives {outer}")
    return buf, t


def _from_ptr(
    ptr: int, t: T.Type, dims: tuple[int, ...], strides: Any, capacity: Any, dev: Device
) -> Any:
    """A buffer over the memory at address ``ptr`` (not owned: the caller keeps it alive)."""
    dtype, inner = np_dtype(t), inner_shape(t)
    size = _type_bytes(t)
    if strides is None:
        outer = tuple(size * math.prod(dims[k + 1 :]) for k in range(len(dims)))
    else:
        outer = tuple(builtins.int(x) for x in strides)
        if len(outer) != len(dims):
            raise KdslError(f"array(ptr=...): {len(outer)} strides for {len(dims)} dimensions")
    full_shape, full_strides = dims + inner, outer + _inner_strides(t)
    extent = 0 if 0 in dims else size + sum((d - 1) * abs(s) for d, s in zip(dims, outer))
    if capacity is not None and extent > builtins.int(capacity):
        raise KdslError(
            f"array(ptr=...): shape {dims} needs {extent} bytes, capacity is {capacity}"
        )
    if ptr == 0 and extent:
        raise KdslError("array(ptr=0) is a null pointer: only an empty shape may use it")
    if dev.is_cuda:
        cp = mem.cupy()
        memory = cp.cuda.UnownedMemory(ptr, extent, None, dev.ordinal)
        return cp.ndarray(full_shape, dtype, cp.cuda.MemoryPointer(memory, 0), full_strides)
    face = {"data": (ptr, False), "shape": full_shape, "strides": full_strides,
            "typestr": dtype.str, "descr": dtype.descr, "version": 3}  # fmt: skip
    return np.asarray(_Interface(face, None))


def from_ptr(
    ptr: int, length: int, dtype: Any = None, shape: Any = None, device: Any = None
) -> array:
    """Warp's deprecated ``from_ptr``: ``ptr`` is the address of a pointer to the data.

    As in Warp, the data address is read from ``ptr`` (a ``size_t`` there), and the
    array of ``length`` elements (``shape`` when given) does not own the memory.
    New code writes ``kdsl.array(ptr=address, dtype=..., shape=..., device=...)``.
    """
    import ctypes

    if dtype is None:
        raise KdslError("from_ptr() needs a dtype")
    addr = 0 if ptr == 0 else ctypes.cast(ptr, ctypes.POINTER(ctypes.c_size_t)).contents.value
    dims = shape if shape is not None else length
    t = resolve_dtype(dtype)
    return array(ptr=addr, dtype=dtype, shape=dims, device=device,
                 capacity=builtins.int(length) * _type_bytes(t))  # fmt: skip


def _reshape_dims(shape: Any, old: tuple[int, ...], size: int) -> tuple[int, ...]:
    """``shape`` for ``reshape()``, its one -1 (if any) worked out from ``size``."""
    if isinstance(shape, builtins.int | np.integer) and not isinstance(shape, builtins.bool):
        shape = (shape,)
    try:
        dims = list(shape)
    except TypeError:
        raise KdslError(
            f"reshape(): shape must be an int or a tuple of ints, got {shape!r}"
        ) from None
    if dims.count(-1) > 1:
        raise KdslError(f"reshape(): only one dimension may be -1, got {tuple(dims)}")
    if -1 in dims:
        at = dims.index(-1)
        dims[at] = 0
        known = int(np.prod([d for k, d in enumerate(dims) if k != at], dtype=np.int64))
        if known == 0 or size % known:
            raise KdslError(f"cannot reshape an array of shape {old} to {tuple(shape)}")
        dims[at] = size // known
    out = normalize_shape(dims)
    if int(np.prod(out, dtype=np.int64)) != size:
        raise KdslError(f"cannot reshape an array of shape {old} (size {size}) to {out}")
    return out


def _type_bytes(t: T.Type) -> int:
    return np_dtype(t).itemsize * math.prod(inner_shape(t))


def _inner_strides(t: T.Type) -> tuple[int, ...]:
    """Byte strides of a contiguous element's component dims (() for scalars and structs)."""
    inner, item = inner_shape(t), np_dtype(t).itemsize
    return tuple(item * math.prod(inner[k + 1 :]) for k in range(len(inner)))


class _Interface:
    # An __array_interface__ over another buffer's memory, keeping that buffer alive.
    def __init__(self, face: dict, owner: Any) -> None:
        self.__array_interface__ = face
        self.owner = owner


def _restride(buf: Any, dev: Device, dtype: np.dtype, shape: tuple, strides: tuple) -> Any:
    """``buf``'s memory, from its first element, as ``shape``/``strides`` of ``dtype``."""
    if dev.is_cuda:
        return mem.cupy().ndarray(shape, dtype, memptr=buf.data, strides=strides)
    face = dict(buf.__array_interface__)
    face.update(shape=tuple(shape), strides=tuple(strides), typestr=dtype.str, descr=dtype.descr)
    return np.asarray(_Interface(face, buf))
