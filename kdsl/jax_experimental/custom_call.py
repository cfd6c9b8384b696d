"""``kdsl.jax_experimental.custom_call.jax_kernel``: Warp's older calling convention.

Warp's first ``jax_kernel`` was built on XLA custom calls (API version 0), which JAX
has deprecated in favour of the FFI; kdsl implements the old signature on top of the
FFI version instead. The number of outputs is not given: every kernel parameter
after the call's arguments is an output, and the launch dims (which also give the
output shapes) are ``launch_dims`` or the shape of the first argument.
"""

from __future__ import annotations

from typing import Any

from kdsl.interop.jax_ffi import JaxFfiError
from kdsl.interop.jax_kernel import FfiKernel


class CustomCallKernel:
    """A kdsl kernel callable from JAX with the custom-call convention."""

    def __init__(self, kernel: Any, launch_dims: Any) -> None:
        if not hasattr(kernel, "arg_types"):
            raise JaxFfiError(f"jax_kernel() takes a @kdsl.kernel, not {type(kernel).__name__}")
        self.kernel = kernel
        self.launch_dims = launch_dims
        self._by_outputs: dict[int, FfiKernel] = {}

    def __call__(self, *args: Any) -> list[Any]:
        """Trace a launch with ``args`` as inputs; returns the list of outputs."""
        n = len(self.kernel.arg_names) - len(args)
        if len(args) < 1 or n < 1:
            raise JaxFfiError(
                f"jax_kernel '{self.kernel.name}': needs at least one input and one output "
                f"(it has {len(self.kernel.arg_names)} parameters, got {len(args)} inputs)"
            )
        ffi = self._by_outputs.get(n)
        if ffi is None:
            ffi = self._by_outputs[n] = FfiKernel(
                self.kernel, n, "broadcast_all", self.launch_dims, None, None
            )
        return ffi(*args)


def jax_kernel(kernel: Any, launch_dims: Any = None, quiet: bool = False) -> CustomCallKernel:
    """A JAX function launching ``kernel`` (inputs first, then outputs; see module docs).

    ``quiet`` is accepted for compatibility: kdsl warns about nothing here.
    """
    return CustomCallKernel(kernel, launch_dims)
