"""Warp's ``warp.jax_experimental`` names: kdsl kernels and functions inside JAX programs.

``jax_kernel`` takes the FFI version's arguments
(``kdsl.jax_experimental.ffi.jax_kernel``, as in Warp 1.10 and later) and also
Warp's older convention, which guides written before 1.10 show (outputs inferred
from the call, see ``kdsl.jax_experimental.conventions``);
``kdsl.jax_experimental.custom_call.jax_kernel`` keeps only the older signature.
Importing this package does not import JAX.
"""

from kdsl.jax_experimental.conventions import jax_kernel
from kdsl.jax_experimental.ffi import GraphMode, jax_callable, register_ffi_callback

__all__ = ["GraphMode", "jax_callable", "jax_kernel", "register_ffi_callback"]
