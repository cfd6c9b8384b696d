"""``jax_callable`` and ``register_ffi_callback``: Python functions as JAX FFI targets.

``jax_callable(func)`` wraps a Python function annotated like a kernel (arrays,
scalars) that launches kdsl kernels; JAX calls it through XLA's FFI with its buffers
seen as kdsl arrays (no copies). ``register_ffi_callback(name, func)`` registers a
bare ``func(inputs, outputs, attrs, ctx)`` under a target name for
``jax.ffi.ffi_call``.

``GraphMode`` says how a call relates to CUDA graphs on a GPU:

- ``JAX`` (default): the call tells XLA it may be captured, so XLA records the
  kernels it launches on XLA's stream into its own CUDA graph (a command buffer) and
  replays them without calling Python again;
- ``KDSL`` (alias ``WARP``): XLA calls Python every time; kdsl captures the
  function's launches into a CUDA graph on the first call with given buffers and
  static arguments, and replays that graph on XLA's stream afterwards;
- ``NONE``: no graphs; the function runs on every call (use it when it synchronizes
  with the host or its launches depend on data read back).

On the CPU there are no graphs: in every mode the function runs on every call, on
XLA's thread, and its launches complete before the call returns.
"""

from __future__ import annotations

import enum
import inspect
from collections.abc import Callable
from typing import Any

from kdsl.errors import KdslError
from kdsl.interop import jax_ffi as F
from kdsl.interop import xla_ffi
from kdsl.runtime.array import array
from kdsl.runtime.device import Device


class GraphMode(enum.IntEnum):
    """How an FFI call is put into CUDA graphs (see the module docstring)."""

    NONE = 0
    JAX = 1
    KDSL = 2
    WARP = 2  # Warp's name for KDSL


def _param_types(func: Callable[..., Any], what: str) -> tuple[list[str], list[Any]]:
    from kdsl.types import type_of

    try:
        sig = inspect.signature(func, eval_str=True)
    except Exception as e:  # an unresolvable string annotation
        raise F.JaxFfiError(f"{what}: cannot read its annotations: {e}") from None
    names, types = [], []
    for name, prm in sig.parameters.items():
        if prm.annotation is inspect.Parameter.empty:
            raise F.JaxFfiError(f"{what}: parameter '{name}' needs a type annotation "
                                f"(e.g. wp.array(dtype=float) or float)")  # fmt: skip
        try:
            types.append(type_of(prm.annotation))
        except (TypeError, KdslError):
            raise F.JaxFfiError(
                f"{what}: the annotation of '{name}' is not a kdsl type: {prm.annotation!r}"
            ) from None
        names.append(name)
    return names, types


class FfiCallable(F.FfiTarget):
    """A Python function callable from JAX (made by ``jax_callable``)."""

    def __init__(
        self,
        func: Callable[..., Any],
        num_outputs: int,
        graph_mode: GraphMode,
        vmap_method: str | None,
        output_dims: Any,
        in_out_argnames: Any,
    ) -> None:
        self.func = func
        fname = getattr(func, "__name__", type(func).__name__)
        what = f"jax_callable '{fname}'"
        names, types = _param_types(func, what)
        self.graph_mode = GraphMode(graph_mode)
        self.graphs: dict[Any, Any] = {}  # GraphMode.KDSL: one CUDA graph per call and buffers
        super().__init__(
            what, names, types, num_outputs, in_out_argnames, vmap_method, output_dims,
            F.unique_name("callable", fname),
        )  # fmt: skip

    def _traits(self, platform: str) -> int:
        if platform == "CUDA" and self.graph_mode is GraphMode.JAX:
            return xla_ffi.TRAIT_COMMAND_BUFFER_COMPATIBLE
        return 0

    def __call__(self, *args: Any, output_dims: Any = None, vmap_method: Any = None) -> list[Any]:
        """Trace a call: returns the outputs (a list; in-out arrays first)."""
        jax = F.jax_module()
        arrays, statics = self._trace_args(args)
        dims = self.output_dims if output_dims is None else output_dims
        out_types = F.output_types(self.what, jax, self.outputs, dims, self._first_dims(args))
        return self._call(jax, args, arrays, out_types, vmap_method, F.static_key(statics), statics)

    def _arguments(self, frame: Any, device: Device, statics: dict) -> tuple[list, list]:
        values, ptrs = [], []
        for p, buf in self._buffers(frame):
            if buf is None:
                values.append(statics[p.name])
                continue
            view, _ = F.fold_batch(F.FfiBuffer(buf, device).view(), p)
            values.append(array._wrap(view, p.type.dtype, device))
            ptrs.append((buf.data or 0, view.shape))
        return values, ptrs

    def _execute(self, frame: Any, platform: str) -> None:
        call_id = xla_ffi.attributes(frame.attrs)[F.CALL_ATTR]
        device = F.call_device(frame, platform)
        values, ptrs = self._arguments(frame, device, self.calls[call_id])
        if device.is_cpu:
            self.func(*values)
            return
        from kdsl.runtime.device import ScopedDevice
        from kdsl.runtime.stream import ScopedStream

        stream = F.call_stream(frame, device)
        if self.graph_mode is not GraphMode.KDSL:
            with ScopedDevice(device), ScopedStream(stream, sync_enter=False):
                self.func(*values)
            return
        key = (device.alias, call_id, tuple(ptrs))
        graph = self.graphs.get(key)
        if graph is None:
            graph = self.graphs[key] = _capture(self.func, values, device)
        graph.launch(stream=stream.cupy)


def _capture(func: Callable[..., Any], values: list, device: Device) -> Any:
    """A CuPy CUDA graph of the launches ``func(*values)`` makes (kdsl's own capture)."""
    from kdsl.runtime import cuda_memory as mem
    from kdsl.runtime.device import ScopedDevice
    from kdsl.runtime.stream import ScopedStream, Stream

    cp = mem.cupy()
    private = Stream(device)
    with ScopedDevice(device), ScopedStream(private, sync_enter=False):
        private.cupy.begin_capture(mode=cp.cuda.runtime.streamCaptureModeRelaxed)
        try:
            func(*values)
        finally:
            graph = private.cupy.end_capture()
    return graph


def jax_callable(
    func: Callable[..., Any],
    num_outputs: int = 1,
    graph_compatible: bool | None = None,
    graph_mode: GraphMode = GraphMode.JAX,
    vmap_method: str | None = "broadcast_all",
    output_dims: Any = None,
    in_out_argnames: Any = None,
) -> FfiCallable:
    """A JAX function calling ``func``, a Python function annotated like a kernel.

    ``func``'s array parameters get kdsl arrays over JAX's buffers; its last
    ``num_outputs`` parameters (plus the in-out ones) are outputs; non-array
    arguments must be static. ``output_dims`` (an int, tuple or dict keyed by output
    name) defaults to the kdsl shape of the first array input. ``graph_compatible``
    is the deprecated spelling of ``graph_mode`` (False means ``GraphMode.NONE``).
    """
    if graph_compatible is not None:
        graph_mode = GraphMode.JAX if graph_compatible else GraphMode.NONE
    return FfiCallable(func, num_outputs, graph_mode, vmap_method, output_dims, in_out_argnames)


class FfiContext:
    """What a ``register_ffi_callback`` function gets besides buffers and attributes."""

    __slots__ = ("device", "platform", "stream")

    def __init__(self, device: Device, platform: str, stream: int) -> None:
        self.device = device  # the kdsl device of the call
        self.platform = platform  # "cpu" or "CUDA"
        self.stream = stream  # XLA's cudaStream_t as an int (0 on the cpu)


def register_ffi_callback(
    name: str, func: Callable[[list, list, dict, FfiContext], None], graph_compatible: bool = True
) -> None:
    """Register ``func(inputs, outputs, attrs, ctx)`` as FFI target ``name``.

    Call it with ``jax.ffi.ffi_call(name, out_types)(*arrays, **attrs)``. ``inputs``
    and ``outputs`` are ``FfiBuffer``s (JAX shapes; pass them to ``kdsl.launch``
    directly), ``attrs`` a dict of the call's attributes, ``ctx`` an ``FfiContext``
    (device and CUDA stream). With ``graph_compatible`` XLA may capture the call's
    GPU work into its CUDA graphs.
    """
    if not isinstance(name, str) or not name:
        raise F.JaxFfiError(f"register_ffi_callback(): name must be a string, got {name!r}")
    if not callable(func):
        raise F.JaxFfiError("register_ffi_callback(): func must be callable")

    def execute(frame: Any, platform: str) -> None:
        device = F.call_device(frame, platform)
        inputs = [F.FfiBuffer(b, device) for b in xla_ffi.buffers(frame.args)]
        outputs = [F.FfiBuffer(b, device) for b in xla_ffi.buffers(frame.rets)]
        attrs = xla_ffi.attributes(frame.attrs)
        stream = 0 if device.is_cpu else xla_ffi.stream_of(frame)
        func(inputs, outputs, attrs, FfiContext(device, platform, stream))

    def traits(platform: str) -> int:
        compatible = graph_compatible and platform == "CUDA"
        return xla_ffi.TRAIT_COMMAND_BUFFER_COMPATIBLE if compatible else 0

    F.register_target(name, execute, traits)


def get_jax_device() -> Device:
    """The kdsl device of JAX's default device."""
    from kdsl.interop.jax import device_from_jax

    jax = F.jax_module()
    default = jax.config.jax_default_device
    if default is None or isinstance(default, str):
        default = jax.devices(default)[0]
    return device_from_jax(default)
