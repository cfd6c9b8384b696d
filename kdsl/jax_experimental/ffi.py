"""``kdsl.jax_experimental.ffi``: Warp's FFI names (``jax_kernel``, ``jax_callable``, ...).

The code lives in ``kdsl.interop.jax_kernel`` and ``kdsl.interop.jax_callable``.
"""

from kdsl.interop.jax_callable import (
    FfiCallable,
    FfiContext,
    GraphMode,
    get_jax_device,
    jax_callable,
    register_ffi_callback,
)
from kdsl.interop.jax_ffi import FfiBuffer, JaxFfiError
from kdsl.interop.jax_kernel import FfiKernel, jax_kernel

__all__ = [
    "FfiBuffer", "FfiCallable", "FfiContext", "FfiKernel", "GraphMode", "JaxFfiError",
    "get_jax_device", "jax_callable", "jax_kernel", "register_ffi_callback",
]  # fmt: skip
