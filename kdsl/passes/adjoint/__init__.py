"""Reverse-mode autodiff: add each kernel's adjoint function (see ``_adjoint``).

``adjoint{kernel=SYM}`` adds ``SYM__adj`` (and ``SYM__count`` when a loop's tape
size is only known at run time) next to the kernel ``SYM``; without ``kernel`` it
does so for every kernel. The adjoint takes the kernel's parameters, then one
adjoint per parameter (``adj_<name>``, same type: gradient arrays for arrays), then
the hidden tape arrays the runtime allocates (``tape<L>_<j>``, ``tape_status``).
Run it after inlining: calls left in the kernel cannot be differentiated.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from kdsl.ir import Module
from kdsl.passes._adjoint import ADJ_SUFFIX, AdjointBuilder
from kdsl.passes.manager import ModulePass


def _is_primal_kernel(func) -> bool:
    attrs = func.attrs
    return attrs.get("kind") == "kernel" and "adjoint_of" not in attrs and "counter_of" not in attrs


@dataclass(frozen=True)
class AdjointPass(ModulePass):
    """Add adjoint (and tape-counting) functions for kernels (see the module docstring)."""

    name: ClassVar[str] = "adjoint"
    #: The kernel to differentiate; empty means every kernel of the module.
    kernel: str = ""

    def apply(self, module: Module) -> bool:
        changed = False
        for func in list(module.funcs):
            sym = func.attrs["sym_name"]
            if not _is_primal_kernel(func) or (self.kernel and sym != self.kernel):
                continue
            if module.has_func(sym + ADJ_SUFFIX):
                continue
            builder = AdjointBuilder(module, func)
            builder.build()
            builder.build_counter()
            changed = True
        return changed
