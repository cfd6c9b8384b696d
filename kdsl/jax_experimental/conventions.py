"""``kdsl.jax_experimental.jax_kernel``: Warp's FFI signature and its older one, both.

Warp 1.10 made ``warp.jax_experimental.jax_kernel`` the FFI version
(``jax_kernel(kernel, num_outputs=1, vmap_method, launch_dims, output_dims,
in_out_argnames)``); code and guides written before use the custom-call one
(``jax_kernel(kernel, launch_dims=None, quiet=False)``: the outputs are the
parameters after the call's arguments). Both spellings work here:

- ``num_outputs``, ``in_out_argnames`` or an ``int`` second argument: the FFI version.
- Otherwise the number of outputs is inferred per call (parameters minus arguments),
  which is the FFI default (one output) whenever that default fits the call, and
  Warp's older convention otherwise. A tuple or list second argument is the older
  ``launch_dims``.

Either way a call returns the list of outputs.
"""

from __future__ import annotations

from typing import Any

from kdsl.interop.jax_kernel import FfiKernel
from kdsl.jax_experimental.custom_call import CustomCallKernel


def jax_kernel(
    kernel: Any,
    num_outputs: Any = None,
    vmap_method: str | None = "broadcast_all",
    launch_dims: Any = None,
    output_dims: Any = None,
    in_out_argnames: Any = None,
    quiet: bool = False,
) -> FfiKernel | CustomCallKernel:
    """A JAX function launching ``kernel``, in Warp's FFI or older convention (module docs).

    ``quiet`` is accepted for compatibility with the older signature.
    """
    if isinstance(num_outputs, tuple | list) and launch_dims is None:
        num_outputs, launch_dims = None, tuple(num_outputs)  # jax_kernel(k, (N, M))
    if num_outputs is not None or in_out_argnames:
        n = 1 if num_outputs is None else num_outputs
        return FfiKernel(kernel, n, vmap_method, launch_dims, output_dims, in_out_argnames)
    return CustomCallKernel(kernel, launch_dims, vmap_method, output_dims, min_inputs=0)
