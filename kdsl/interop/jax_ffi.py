"""What kdsl's JAX FFI calls share: targets, parameter specs, shapes and buffers.

A kdsl kernel (``jax_kernel``) or Python function (``jax_callable``) becomes an XLA
FFI target: a ctypes handler registered with ``jax.ffi.register_ffi_target``
(``api_version=1``) for the ``cpu`` and ``CUDA`` platforms. ``jax.ffi.ffi_call``
puts a call to it into the traced program; when XLA runs the program it calls the
handler with the input and output buffers (``kdsl.interop.xla_ffi``), which are
wrapped as kdsl arrays without copies. Values that JAX cannot pass as buffers
(static scalars, launch dims) are fixed at trace time and found again through an
integer attribute, ``kdsl_call``.

Under ``jax.vmap`` with ``vmap_method="broadcast_all"`` (or ``"expand_dims"``) the
buffers gain leading batch dims. As in Warp, they are folded into the first dim of
each array, and the first launch dim is multiplied by the batch size: right for
kernels whose threads each handle one element of every array (element-wise), not for
kernels that index across the first dim. Use ``vmap_method="sequential"`` for those.
"""

from __future__ import annotations

import ctypes
import itertools
import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from kdsl.errors import KdslError
from kdsl.interop import xla_ffi
from kdsl.interop.dtypes import InteropTypeError
from kdsl.interop.jax import dtype_from_jax, is_tracer
from kdsl.ir import types as T
from kdsl.runtime.device import Device, get_device
from kdsl.types import class_of

PLATFORMS = ("cpu", "CUDA")  # JAX's spellings, case-sensitive
CALL_ATTR = "kdsl_call"
VMAP_METHODS = ("broadcast_all", "expand_dims", "sequential", "sequential_unrolled")

# ctypes handlers must outlive every compiled program that calls them.
_HANDLERS: list[Any] = []
_names = itertools.count()


class JaxFfiError(KdslError, ValueError):
    """Bad use of ``jax_kernel``/``jax_callable`` (also a ``ValueError``, as Warp raises)."""


def jax_module() -> Any:
    """``jax``, checked to have the FFI (JAX 0.5 or newer)."""
    try:
        import jax
    except ImportError:
        raise KdslError("jax_kernel/jax_callable need JAX (pip install jax)") from None
    if not hasattr(getattr(jax, "ffi", None), "ffi_call"):
        raise KdslError(f"jax_kernel/jax_callable need JAX 0.5 or newer (have {jax.__version__})")
    return jax


def unique_name(prefix: str, name: str) -> str:
    """A target name no other kdsl target uses."""
    return f"kdsl_{prefix}_{name}_{next(_names)}"


def register_target(
    name: str, execute: Callable[[Any, str], None], traits: Callable[[str], int]
) -> None:
    """Register ``execute(frame, platform)`` as FFI target ``name`` on every platform.

    ``traits(platform)`` answers XLA's metadata query (e.g. CUDA-graph compatible).
    An exception in ``execute`` becomes an XLA error, raised by JAX as a
    ``JaxRuntimeError`` carrying its message.
    """
    jax = jax_module()
    for platform in PLATFORMS:

        def handler(frame_ptr: Any, platform: str = platform) -> Any:
            frame = frame_ptr.contents
            try:
                if xla_ffi.answer_metadata(frame, traits(platform)):
                    return None
                if frame.stage == xla_ffi.STAGE_EXECUTE:
                    execute(frame, platform)
                return None
            except Exception as e:  # every error must reach JAX, not crash XLA
                return xla_ffi.make_error(frame, f"{name}: {type(e).__name__}: {e}")

        fn = xla_ffi.Handler(handler)
        _HANDLERS.append(fn)
        capsule = jax.ffi.pycapsule(ctypes.cast(fn, ctypes.c_void_p).value)
        jax.ffi.register_ffi_target(name, capsule, platform=platform, api_version=1)


@dataclass(frozen=True)
class Param:
    """One parameter of the kernel or function: its name, IR type and role."""

    name: str
    type: T.Type
    in_out: bool = False

    @property
    def is_array(self) -> bool:
        """Whether it is an array (a JAX buffer) rather than a static value."""
        return isinstance(self.type, T.ArrayType)

    @property
    def ndim(self) -> int:
        """The kdsl dims of the array."""
        return self.type.ndim

    @property
    def inner(self) -> tuple[int, ...]:
        """Element dims a vector/matrix dtype adds on the JAX side."""
        return T.value_shape(self.type.dtype)

    @property
    def np_dtype(self) -> np.dtype:
        """The NumPy (and JAX) dtype of the array's components."""
        return T.elem_type(self.type.dtype).np_dtype

    @property
    def jax_ndim(self) -> int:
        """The dims of the array on the JAX side."""
        return self.ndim + len(self.inner)

    def describe(self) -> str:
        """``"array of vec3f with 1 dims"``, for messages."""
        if self.is_array:
            return f"{self.ndim}-d array of {class_of(self.type.dtype).__name__}"
        return str(self.type)


def split_params(
    what: str,
    names: Sequence[str],
    types: Sequence[T.Type],
    num_outputs: int,
    in_out_argnames: Any,
) -> tuple[list[Param], list[Param]]:
    """The inputs (in_out ones flagged) and the pure outputs of a parameter list."""
    in_out = set([in_out_argnames] if isinstance(in_out_argnames, str) else in_out_argnames or ())
    unknown = in_out - set(names)
    if unknown:
        raise JaxFfiError(f"{what}: in_out_argnames names no parameter: {sorted(unknown)}")
    if not isinstance(num_outputs, int) or isinstance(num_outputs, bool) or num_outputs < 1:
        raise JaxFfiError(f"{what}: num_outputs must be an int >= 1, got {num_outputs!r}")
    pure = num_outputs - len(in_out)
    if pure < 0:
        raise JaxFfiError(
            f"{what}: num_outputs={num_outputs} must count the {len(in_out)} in_out arguments too"
        )
    if pure > len(names):
        raise JaxFfiError(
            f"{what}: num_outputs={num_outputs} but it has only {len(names)} parameters"
        )
    params = [Param(n, t, n in in_out) for n, t in zip(names, types)]
    inputs, outputs = params[: len(params) - pure], params[len(params) - pure :]
    for p in outputs:
        if p.in_out:
            raise JaxFfiError(
                f"{what}: in_out argument '{p.name}' must come before the {pure} output(s); "
                f"outputs are the last num_outputs - len(in_out_argnames) parameters"
            )
        if not p.is_array:
            raise JaxFfiError(
                f"{what}: output '{p.name}' is a {p.type}, but outputs must be arrays "
                f"(is num_outputs={num_outputs} right?)"
            )
    for p in inputs:
        if p.in_out and not p.is_array:
            raise JaxFfiError(f"{what}: in_out argument '{p.name}' must be an array")
    return inputs, outputs


def check_array(what: str, p: Param, value: Any) -> None:
    """Raise unless ``value`` is a JAX array (or tracer) that fits parameter ``p``."""
    shape, dtype = getattr(value, "shape", None), getattr(value, "dtype", None)
    if shape is None or dtype is None or isinstance(value, np.generic):
        raise JaxFfiError(
            f"{what}: argument '{p.name}' must be a JAX array ({p.describe()}), "
            f"got {type(value).__name__}"
        )
    dtype_from_jax(dtype)  # bfloat16, complex...: no kdsl equivalent
    if np.dtype(dtype) != p.np_dtype:
        raise InteropTypeError(
            f"{what}: argument '{p.name}' must have dtype {p.np_dtype.name} "
            f"({p.describe()}), got {np.dtype(dtype).name}"
        )
    if len(shape) != p.jax_ndim or tuple(shape[p.ndim :]) != p.inner:
        want = f"(*{p.ndim} dims, {', '.join(map(str, p.inner))})" if p.inner else f"{p.ndim}"
        raise JaxFfiError(
            f"{what}: argument '{p.name}' ({p.describe()}) needs a JAX array with "
            f"{want} dims, got shape {tuple(shape)}"
        )


def static_value(what: str, p: Param, value: Any, device: Device) -> Any:
    """A static (trace-time) argument checked and converted for launches."""
    from kdsl.runtime.args import ArgError, convert

    if is_tracer(value):
        raise JaxFfiError(
            f"{what}: argument '{p.name}' ({p.type}) is a traced value; non-array "
            f"arguments are baked in at trace time, so they must be constants or static "
            f"(jax.jit(..., static_argnames=['{p.name}']))"
        )
    try:
        convert(p.type, value, device)
    except ArgError as e:
        raise JaxFfiError(f"{what}: argument '{p.name}': {e}") from None
    return value


def as_dims(dims: Any, what: str) -> tuple[int, ...]:
    """An int or a sequence of ints as a shape tuple."""
    if isinstance(dims, int | np.integer) and not isinstance(dims, bool):
        return (int(dims),)
    try:
        out = tuple(int(d) for d in dims)
    except TypeError:
        raise JaxFfiError(f"{what} must be an int or a tuple of ints, got {dims!r}") from None
    if any(d < 0 for d in out):
        raise JaxFfiError(f"{what} must be non-negative, got {dims!r}")
    return out


def output_shape(what: str, p: Param, dims: Any) -> tuple[int, ...]:
    """The JAX shape of output ``p``; ``dims`` in kdsl (n,) or JAX (n, 3) convention."""
    shape = as_dims(dims, f"{what}: output_dims of '{p.name}'")
    if len(shape) == p.ndim:
        return shape + p.inner
    if len(shape) == p.jax_ndim and shape[p.ndim :] == p.inner:
        return shape
    raise JaxFfiError(
        f"{what}: output '{p.name}' is a {p.describe()}, but its dims would be {shape}; "
        f"give output_dims (an int, a tuple, or a dict keyed by output name)"
    )


def output_types(
    what: str, jax: Any, outputs: Sequence[Param], output_dims: Any, default: Any
) -> list[Any]:
    """``jax.ShapeDtypeStruct``s of the pure outputs."""
    types = []
    for p in outputs:
        if isinstance(output_dims, dict):
            if p.name not in output_dims:
                raise JaxFfiError(f"{what}: output_dims has no entry for output '{p.name}'")
            dims = output_dims[p.name]
        else:
            dims = default if output_dims is None else output_dims
        if dims is None:
            raise JaxFfiError(f"{what}: cannot infer the shape of output '{p.name}'; "
                              f"give output_dims")  # fmt: skip
        types.append(jax.ShapeDtypeStruct(output_shape(what, p, dims), p.np_dtype))
    return types


class CallTable:
    """Trace-time data of the calls of one target, found again by an int id."""

    def __init__(self) -> None:
        self._ids: dict[Any, int] = {}
        self._data: list[Any] = []

    def add(self, key: Any, data: Any) -> int:
        """The id of ``data`` (equal keys share one id, so retracing does not grow the table)."""
        i = self._ids.get(key)
        if i is None:
            i = self._ids[key] = len(self._data)
            self._data.append(data)
        return i

    def __getitem__(self, i: int) -> Any:
        return self._data[i]


def static_key(values: dict[str, Any]) -> Any:
    """A hashable key for static values (NumPy data by bytes)."""
    out = []
    for k, v in sorted(values.items()):
        arr = np.asarray(v) if not isinstance(v, int | float | bool) else None
        out.append((k, type(v).__name__, v if arr is None else (arr.dtype.str, arr.tobytes())))
    return tuple(out)


class FfiBuffer:
    """An input or output buffer of an FFI call, without copying.

    ``shape`` and ``dtype`` are JAX's (vector components are inner dims); ``data`` is
    the address. It exposes ``__array_interface__`` (cpu) or
    ``__cuda_array_interface__`` (GPU), so ``kdsl.launch`` and NumPy/CuPy take it.
    """

    __slots__ = ("data", "device", "dtype", "shape")

    def __init__(self, buf: xla_ffi.Buffer, device: Device) -> None:
        self.shape = xla_ffi.buffer_shape(buf)
        self.dtype = xla_ffi.numpy_dtype(buf.dtype)
        self.data = buf.data or 0
        self.device = device

    def _face(self, version: int) -> dict:
        return {"shape": self.shape, "typestr": self.dtype.str, "data": (self.data, False),
                "strides": None, "version": version}  # fmt: skip

    @property
    def __array_interface__(self) -> dict:
        if not self.device.is_cpu:
            raise AttributeError("a GPU buffer has no __array_interface__")
        return self._face(3)

    @property
    def __cuda_array_interface__(self) -> dict:
        if self.device.is_cpu:
            raise AttributeError("a CPU buffer has no __cuda_array_interface__")
        return self._face(2)

    def view(self) -> Any:
        """The buffer as a NumPy (cpu) or CuPy (GPU) array over the same memory."""
        if math.prod(self.shape) == 0:
            from kdsl.runtime import cuda_memory as mem

            return mem.xp(self.device).empty(self.shape, self.dtype)
        if self.device.is_cpu:
            return np.asarray(self)
        from kdsl.runtime import cuda_memory as mem

        return mem.wrap_cuda(self)[0]

    def __repr__(self) -> str:
        return f"FfiBuffer({self.dtype.name}, shape={self.shape}, device='{self.device}')"


def fold_batch(buf: Any, p: Param) -> tuple[Any, int]:
    """``buf`` with vmap's leading batch dims folded into its first dim, and the batch size."""
    extra = buf.ndim - p.jax_ndim
    if extra <= 0:
        return buf, 1
    batch = math.prod(buf.shape[:extra])
    return buf.reshape(batch * buf.shape[extra], *buf.shape[extra + 1 :]), batch


def call_device(frame: Any, platform: str) -> Device:
    """The kdsl device an FFI call runs on."""
    if platform == "cpu":
        return get_device("cpu")
    ordinal = xla_ffi.device_ordinal(frame)
    if ordinal is None:
        from kdsl.runtime import cuda_memory as mem

        ordinal = mem.cupy().cuda.runtime.getDevice()
    return get_device(f"cuda:{ordinal}")


_STREAMS: dict[tuple[int, int], Any] = {}


def call_stream(frame: Any, device: Device) -> Any:
    """The kdsl ``Stream`` over XLA's CUDA stream for this call (None on the cpu)."""
    if device.is_cpu:
        return None
    handle = xla_ffi.stream_of(frame)
    key = (device.ordinal, handle)
    stream = _STREAMS.get(key)
    if stream is None:
        from kdsl.runtime.stream import Stream

        stream = _STREAMS[key] = Stream(device, cuda_stream=handle)
    return stream


def jax_devices_to_preload(jax: Any) -> list[Device]:
    """The kdsl devices of JAX's default backend (kernels are compiled for them at trace)."""
    from kdsl.interop.jax import device_from_jax

    try:
        return [device_from_jax(d) for d in jax.local_devices()]
    except KdslError:
        return []


class FfiTarget:
    """What a ``jax_kernel`` and a ``jax_callable`` share: one registered FFI target.

    It splits the parameters into inputs and outputs, aliases the in-out inputs to
    their outputs, keeps the trace-time data of each call in a ``CallTable``, and
    puts calls into traced programs. A subclass sets its own attributes before
    calling ``__init__`` (which registers the target) and gives
    ``_execute(frame, platform)`` and ``_traits(platform)``.
    """

    def __init__(self, what: str, names: Sequence[str], types: Sequence[T.Type], num_outputs: int,
                 in_out_argnames: Any, vmap_method: Any, output_dims: Any, name: str):  # fmt: skip
        self.what = what
        self.inputs, self.outputs = split_params(what, names, types, num_outputs, in_out_argnames)
        self.vmap_method = vmap_method
        self.output_dims = output_dims
        arrays = [p for p in self.inputs if p.is_array]
        self.in_out = [p for p in arrays if p.in_out]
        # Input i (counting array inputs) is output j: XLA then passes one buffer.
        self.aliases = {arrays.index(p): j for j, p in enumerate(self.in_out)}
        self.calls = CallTable()
        self.name = name
        register_target(name, self._execute, self._traits)

    def _execute(self, frame: Any, platform: str) -> None:
        raise NotImplementedError

    def _traits(self, platform: str) -> int:
        raise NotImplementedError

    def _trace_args(self, args: tuple, hint: str = "") -> tuple[list, dict[str, Any]]:
        """The array arguments of a call and its static values by name, checked."""
        if len(args) != len(self.inputs):
            names = ", ".join(p.name for p in self.inputs)
            raise JaxFfiError(
                f"{self.what}: expected {len(self.inputs)} input(s) ({names}), got {len(args)}"
                + hint
            )
        cpu = get_device("cpu")
        arrays, statics = [], {}
        for p, v in zip(self.inputs, args):
            if p.is_array:
                check_array(self.what, p, v)
                arrays.append(v)
            else:
                statics[p.name] = static_value(self.what, p, v, cpu)
        return arrays, statics

    def _first_dims(self, args: tuple) -> tuple[int, ...] | None:
        """The kdsl shape of the first array argument (None without one)."""
        for p, v in zip(self.inputs, args):
            if p.is_array:
                return tuple(int(d) for d in v.shape[: p.ndim])
        return None

    def _call(
        self, jax: Any, args: tuple, arrays: list, out_types: list, vmap_method: Any, key: Any,
        data: Any,
    ) -> list[Any]:  # fmt: skip
        """Put a call into the traced program: the in-out outputs, then ``out_types``."""
        in_out = [jax.ShapeDtypeStruct(v.shape, v.dtype)
                  for p, v in zip(self.inputs, args) if p.in_out]  # fmt: skip
        method = self.vmap_method if vmap_method is None else vmap_method
        if method is not None and method not in VMAP_METHODS:
            raise JaxFfiError(f"{self.what}: vmap_method must be one of {VMAP_METHODS}")
        call_id = self.calls.add(key, data)
        call = jax.ffi.ffi_call(
            self.name, in_out + out_types, vmap_method=method,
            input_output_aliases=self.aliases or None,
        )  # fmt: skip
        return call(*arrays, **{CALL_ATTR: np.int64(call_id)})

    def _buffers(self, frame: Any) -> Iterator[tuple[Param, Any]]:
        """Each parameter of an executing call with its XLA buffer (None when static)."""
        ins = iter(xla_ffi.buffers(frame.args))
        outs = xla_ffi.buffers(frame.rets)
        pure = iter(outs[len(self.in_out) :])
        n_in_out = 0
        for p in (*self.inputs, *self.outputs):
            if not p.is_array:
                yield p, None
                continue
            buf = next(ins) if p in self.inputs else next(pure)
            if p.in_out:  # the aliased output buffer holds the input's data
                buf, n_in_out = outs[n_in_out], n_in_out + 1
            yield p, buf
