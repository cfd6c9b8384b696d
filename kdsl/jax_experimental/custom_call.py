"""``kdsl.jax_experimental.custom_call.jax_kernel``: Warp's older calling convention.

Warp's first ``jax_kernel`` was built on XLA custom calls (API version 0), which JAX
has deprecated in favour of the FFI; kdsl implements the old signature on top of the
FFI version instead. The number of outputs is not given: every kernel parameter
after the call's arguments is an output, and the launch dims (which also give the
output shapes) are ``launch_dims`` or the shape of the first argument. A call
returns the list of outputs, so ``x, y = f(a, b, c)`` unpacks two of them.
"""

from __future__ import annotations

from typing import Any

from kdsl.interop.jax_ffi import JaxFfiError
from kdsl.interop.jax_kernel import FfiKernel


class CustomCallKernel:
    """A kdsl kernel callable from JAX whose outputs are the parameters after the call's
    arguments (at least ``min_inputs`` of them, and at least one output)."""

    def __init__(
        self,
        kernel: Any,
        launch_dims: Any,
        vmap_method: str | None = "broadcast_all",
        output_dims: Any = None,
        min_inputs: int = 1,
    ) -> None:
        if not hasattr(kernel, "arg_types"):
            raise JaxFfiError(f"jax_kernel() takes a @kdsl.kernel, not {type(kernel).__name__}")
        self.kernel = kernel
        self.launch_dims = launch_dims
        self.vmap_method = vmap_method
        self.output_dims = output_dims
        self.min_inputs = min_inputs
        self._by_outputs: dict[int, FfiKernel] = {}

    def __call__(self, *args: Any, **per_call: Any) -> list[Any]:
        """Trace a launch with ``args`` as inputs; returns the list of outputs.

        Keywords (``launch_dims``, ``output_dims``, ``vmap_method``) override the
        defaults for this call, as with the FFI version.
        """
        n = len(self.kernel.arg_names) - len(args)
        if len(args) < self.min_inputs or n < 1:
            need = f"at least {self.min_inputs} input(s) and " if self.min_inputs else ""
            raise JaxFfiError(
                f"jax_kernel '{self.kernel.name}': needs {need}at least one output "
                f"(it has {len(self.kernel.arg_names)} parameters, got {len(args)} inputs; "
                "the parameters after the inputs are the outputs)"
            )
        ffi = self._by_outputs.get(n)
        if ffi is None:
            ffi = self._by_outputs[n] = FfiKernel(
                self.kernel, n, self.vmap_method, self.launch_dims, self.output_dims, None
            )
        return ffi(*args, **per_call)


def jax_kernel(kernel: Any, launch_dims: Any = None, quiet: bool = False) -> CustomCallKernel:
    """A JAX function launching ``kernel`` (inputs first, then outputs; see module docs).

    ``quiet`` is accepted for compatibility: kdsl warns about nothing here.
    """
    return CustomCallKernel(kernel, launch_dims)
