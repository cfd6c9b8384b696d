"""What a cache hit needs to know of the generated CUDA C without generating it.

The kernel cache loads a cubin by the C name of its kernel's entry, and a launch needs
the block size and the thread index's dimensions: these small facts live here, so that
a warm start imports neither the code generator (``lower``, ``emitter``, the op table)
nor its dataclasses. ``lower`` generates code that follows them.
"""

from __future__ import annotations

from kdsl.backends.cuda import ctypes_ as CT
from kdsl.ir.core import Module, Operation

#: Threads per block.
BLOCK = 256
#: The name NVRTC gives the generated unit (and the ``#line`` directives use for it).
UNIT_NAME = "kdsl_module.cu"


def tid_ndims(func: Operation) -> set[int]:
    """The ``ndim`` of every ``kd.tid`` in ``func``."""
    return {op.attrs["ndim"] for op in func.walk() if op.name == "kd.tid"}


def kernel_names(module: Module) -> list[str]:
    """Symbols of the kernels of ``module``."""
    return [f.attrs["sym_name"] for f in module.funcs if f.attrs.get("kind") == "kernel"]


def entry_name(symbol: str) -> str:
    """The C name ``lower.generate(module, [symbol])`` gives kernel ``symbol``: known
    without generating, so a kernel whose cubin comes from the cache is never lowered."""
    return f"k_{CT.sanitize(symbol)}_0"


def fast_entry_name(symbol: str) -> str:
    """The C name of kernel ``symbol``'s fast entry (``variants``), where it has one."""
    return entry_name(symbol) + "_fast"
