"""Backends: the plugin interface, the registry and the built-in backends.

Importing this package imports no backend; they load on first use.
"""

from kdsl.backends.base import Backend, CompiledKernel
from kdsl.backends.registry import (
    available_backends,
    get_backend,
    load_failures,
    register_backend,
)

__all__ = [
    "Backend", "CompiledKernel", "available_backends", "get_backend", "load_failures",
    "register_backend",
]  # fmt: skip
