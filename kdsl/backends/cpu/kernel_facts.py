"""What the cpu backend needs to know about a kernel without lowering it.

Loading a cached kernel reads these from the optimized IR; they live apart from
``lower`` so that a cache hit imports no part of llvmlite.
"""

from __future__ import annotations

from kdsl.ir.core import Module, Operation


def kernel_symbol(name: str) -> str:
    """The LLVM name of the range function of kernel ``name``."""
    return f"kdsl_kernel_{name}"


def kernel_names(module: Module) -> list[str]:
    """Symbols of the kernels of ``module``."""
    return [f.attrs["sym_name"] for f in module.funcs if f.attrs.get("kind") == "kernel"]


def tid_ndims(func: Operation) -> set[int]:
    """The ``ndim`` of every ``kd.tid`` in ``func``."""
    return {op.attrs["ndim"] for op in func.walk() if op.name == "kd.tid"}


def uses_print(module: Module) -> bool:
    """True when ``module`` holds a ``kd.print``."""
    return any(op.name == "kd.print" for op in module.walk())
