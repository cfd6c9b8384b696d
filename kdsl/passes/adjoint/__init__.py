"""Reverse-mode autodiff: the ``adjoint`` pass adds each kernel's adjoint function.

``adjoint{kernel=SYM}`` adds ``SYM__adj`` (and ``SYM__count`` when a loop's tape
size is only known at run time) next to the kernel ``SYM``; without ``kernel`` it
does so for every kernel. The adjoint takes the kernel's parameters, then one
adjoint per parameter (``adj_<name>``, same type: gradient arrays for arrays), then
the hidden tape arrays the runtime allocates (``tape<L>_<j>``, ``tape_status``).
Run it after inlining: calls left in the kernel cannot be differentiated.

Strategy (documented for users in ``docs/autodiff.md``), one file per job:

- **Forward replay, then reverse sweep** (``replay``, ``reverse``). The adjoint
  function first recomputes the kernel's values (stores and atomics are skipped:
  the outputs already hold them), then walks the ops backwards applying each op's
  VJP rule from the catalog. Reads of an array become atomic adds into its
  gradient array; writes read the output's gradient.
- **Regions recompute.** Values inside an ``scf.if`` branch or a loop body are not
  visible outside it, so the reverse of a region first replays the region (from
  its arguments) and then reverses it. ``if`` reverses the branch that ran.
- **Loops tape their carried values** (``tapes``, ``reverse_loops``). Replaying a
  loop stores the values it carries into each iteration in a per-thread tape; the
  reverse loop runs the iterations backwards, reloads iteration k's carried values,
  replays the body from them and reverses it. ``while`` loops (and the flags
  ``break`` and ``continue`` become) are handled the same way, so loop-carried
  gradients are exact. A loop nested in another is taped again inside each reversed
  outer iteration, so its tape holds one instance at a time.
- **Tape sizes** (``counting``). A loop with constant bounds has a static size.
  Otherwise the counting function runs first and the runtime allocates exactly what
  the adjoint needs, refusing with a clear error above a memory limit. A mismatch
  at run time (possible only with nondeterministic control flow) sets a status flag
  the runtime turns into an error: a gradient is never silently wrong.

``analysis`` holds what both sweeps ask about the kernel (which loops matter, which
arrays a thread owns) and the refusals; ``builder`` puts the adjoint function
together. The ``tape-dce`` pass later drops the tapes the simplified reverse sweep
never reads.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from kdsl.ir import Module, Operation
from kdsl.passes.adjoint.builder import ADJ_SUFFIX, AdjointBuilder
from kdsl.passes.adjoint.counting import COUNT_SUFFIX
from kdsl.passes.manager import ModulePass


def _is_primal_kernel(func: Operation) -> bool:
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


__all__ = ["ADJ_SUFFIX", "COUNT_SUFFIX", "AdjointBuilder", "AdjointPass"]
