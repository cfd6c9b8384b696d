"""Drop the tape traffic an adjoint does not need.

The adjoint pass tapes every value a loop carries, but once the pipeline has
simplified the reverse sweep many of them are never read back (a running sum's
old value, say, plays no part in its gradient). This pass removes the stores into
tape arrays that nothing loads from, and the guard around them (``scf.if`` with a
``tape_guard`` attribute) once it guards nothing. The runtime then sees the tape
parameter unused and gives it no memory; when no tape is used it also skips the
counting pass.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from kdsl.ir import Module, Operation
from kdsl.passes.adjoint.tapes import TAPE_GUARD, is_tape_param
from kdsl.passes.manager import ModulePass


def _tapes(func: Operation) -> list:
    """The adjoint's tape parameters: hidden ones (past ``hidden_from``) named ``tape<L>_<j>``."""
    args = func.regions[0].block.args[func.attrs["hidden_from"] :]
    return [a for a in args if is_tape_param(a.name_hint)]


def _read(arg) -> bool:
    # The guard's kd.array_shape is not a read of the tape's contents.
    return any(op.name == "kd.load" for op, _ in arg.uses)


@dataclass(frozen=True)
class TapeDCEPass(ModulePass):
    """Remove stores into tape arrays nothing reads (see the module docstring)."""

    name: ClassVar[str] = "tape-dce"

    def apply(self, module: Module) -> bool:
        changed = False
        for func in module.funcs:
            if "adjoint_of" not in func.attrs:
                continue
            for arg in _tapes(func):
                if not _read(arg):
                    for op, _ in list(arg.uses):
                        if op.name == "kd.store":
                            op.erase()
                            changed = True
            for op in list(func.walk()):
                if op.name == "scf.if" and TAPE_GUARD in op.attrs and _guards_nothing(op):
                    op.erase()
                    changed = True
        return changed


def _guards_nothing(guard: Operation) -> bool:
    then = guard.regions[0].block
    return all(op.opdef.is_terminator for op in then.ops)
