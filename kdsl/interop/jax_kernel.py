"""``jax_kernel``: a kdsl kernel as a JAX function, through XLA's FFI.

The kernel's parameters are its inputs (arrays, and static scalars fixed at trace
time) followed by its ``num_outputs`` outputs, which include the in-out arrays named
by ``in_out_argnames``: those are inputs aliased to outputs, so the kernel updates
them in place and the call returns their new values first. A call returns a list of
outputs (in-out ones first), whatever their number. See ``kdsl.interop.jax_ffi``
for the mechanism and for how ``vmap`` batches.
"""

from __future__ import annotations

from typing import Any

from kdsl.interop import jax_ffi as F
from kdsl.interop import xla_ffi
from kdsl.runtime.descriptor import ArrayDescriptor

#: Calls whose launch arguments a kernel keeps (the table is cleared when full). A
#: call repeated on buffers at the same addresses (XLA reuses its allocations) then
#: hands ``launch`` the same views, whose packed form the launch reuses in turn.
MAX_PREPARED = 64
_CALL_ATTR = F.CALL_ATTR.encode()


class FfiKernel(F.FfiTarget):
    """A kdsl kernel callable from JAX (made by ``jax_kernel``)."""

    def __init__(
        self,
        kernel: Any,
        num_outputs: int,
        vmap_method: str | None,
        launch_dims: Any,
        output_dims: Any,
        in_out_argnames: Any,
    ) -> None:
        if not hasattr(kernel, "arg_types") or not hasattr(kernel, "build_module"):
            raise F.JaxFfiError(f"jax_kernel() takes a @kdsl.kernel, not {type(kernel).__name__}")
        self.kernel = kernel
        self.launch_dims = launch_dims
        self._preloaded: set[str] = set()
        #: Launch arguments by call and buffer layout (see ``_execute``).
        self._prepared: dict[tuple, tuple[list, Any]] = {}
        super().__init__(
            f"jax_kernel '{kernel.name}'", kernel.arg_names, kernel.arg_types, num_outputs,
            in_out_argnames, vmap_method, output_dims, F.unique_name("kernel", kernel.key),
        )  # fmt: skip

    def _traits(self, platform: str) -> int:
        # A kernel launch may be captured into XLA's CUDA graphs (command buffers).
        return xla_ffi.TRAIT_COMMAND_BUFFER_COMPATIBLE if platform == "CUDA" else 0

    def __call__(
        self, *args: Any, output_dims: Any = None, launch_dims: Any = None,
        vmap_method: Any = None,
    ) -> list[Any]:  # fmt: skip
        """Trace a launch: returns the outputs (a list; in-out arrays first)."""
        jax = F.jax_module()
        hint = "; outputs are not passed (num_outputs counts them)"
        arrays, statics = self._trace_args(args, hint)
        dims = self._launch_dims(launch_dims, args)
        default_out = self.output_dims if output_dims is None else output_dims
        out_types = F.output_types(self.what, jax, self.outputs, default_out, dims)
        self._preload(jax)
        key = (F.static_key(statics), dims)
        return self._call(jax, args, arrays, out_types, vmap_method, key, (statics, dims))

    def _launch_dims(self, launch_dims: Any, args: tuple) -> tuple[int, ...]:
        dims = self.launch_dims if launch_dims is None else launch_dims
        if dims is not None:
            out = F.as_dims(dims, f"{self.what}: launch_dims")
            if not 1 <= len(out) <= 4:
                raise F.JaxFfiError(f"{self.what}: launch_dims must have 1 to 4 dims, got {dims}")
            return out
        first = self._first_dims(args)
        if first is None:
            raise F.JaxFfiError(
                f"{self.what}: the kernel has no array input to infer the launch dims from; "
                f"give launch_dims"
            )
        return first

    def _preload(self, jax: Any) -> None:
        # Compile now, not inside XLA's call (which may be under CUDA graph capture).
        from kdsl.runtime.launch import launch_plan

        for dev in F.jax_devices_to_preload(jax):
            if dev.alias not in self._preloaded:
                launch_plan(self.kernel, dev, None)
                self._preloaded.add(dev.alias)

    def _execute(self, frame: Any, platform: str) -> None:
        from kdsl.runtime.launch import launch

        device = F.call_device(frame, platform)
        # Everything the launch arguments depend on: the call (its statics and dims),
        # the device, and each buffer's address, dtype and dims (vmap batches them).
        key = (
            xla_ffi.int_attribute(frame.attrs, _CALL_ATTR), device,
            xla_ffi.buffer_layouts(frame.args), xla_ffi.buffer_layouts(frame.rets),
        )  # fmt: skip
        prepared = self._prepared.get(key)
        if prepared is None:
            if len(self._prepared) >= MAX_PREPARED:
                self._prepared.clear()
            prepared = self._prepared[key] = self._arguments(frame, device, key[0])
        values, dims = prepared
        launch(self.kernel, dims, inputs=values, device=device,
               stream=F.call_stream(frame, device), record_tape=False)  # fmt: skip

    def _arguments(self, frame: Any, device: Any, call_id: Any) -> tuple[list, Any]:
        """The launch arguments (views of XLA's buffers, statics) and dims of a call."""
        statics, dims = self.calls[call_id]
        values, batch = [], 1
        for p, buf in self._buffers(frame):
            if buf is None:
                values.append(statics[p.name])
                continue
            view, b = F.fold_batch(F.FfiBuffer(buf, device).view(), p)
            batch = max(batch, b)
            values.append(ArrayDescriptor(view, p.type.dtype, device))
        if batch > 1:
            dims = (dims[0] * batch, *dims[1:])
        return values, dims[0] if len(dims) == 1 else dims  # an int: launch's quickest grid


def jax_kernel(
    kernel: Any,
    num_outputs: int = 1,
    vmap_method: str | None = "broadcast_all",
    launch_dims: Any = None,
    output_dims: Any = None,
    in_out_argnames: Any = None,
) -> FfiKernel:
    """A JAX function launching ``kernel`` (usable inside ``jax.jit``, ``vmap``, ``shard_map``).

    ``num_outputs`` counts the kernel's last parameters that are outputs, including
    the in-out arrays named by ``in_out_argnames``. Non-array arguments must be
    static (constants at trace time). ``launch_dims`` defaults to the kdsl shape of
    the first array argument; ``output_dims`` (an int, a tuple, or a dict keyed by
    output name, in the kdsl or the JAX convention) defaults to the launch dims.
    ``launch_dims``, ``output_dims`` and ``vmap_method`` may also be given per call.
    Runs on JAX's CPU (kdsl ``cpu`` backend) and CUDA (kdsl ``cuda`` backend, on
    XLA's stream) devices.
    """
    return FfiKernel(kernel, num_outputs, vmap_method, launch_dims, output_dims, in_out_argnames)
