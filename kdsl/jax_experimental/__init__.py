"""Warp's ``warp.jax_experimental`` names: kdsl kernels and functions inside JAX programs.

``jax_kernel`` is the FFI version (``kdsl.jax_experimental.ffi.jax_kernel``), as in
Warp 1.10 and later; ``kdsl.jax_experimental.custom_call.jax_kernel`` keeps the old
calling convention on top of it. Importing this package does not import JAX.
"""

from kdsl.jax_experimental.ffi import GraphMode, jax_callable, jax_kernel, register_ffi_callback

__all__ = ["GraphMode", "jax_callable", "jax_kernel", "register_ffi_callback"]
