"""What the pass-manager tests run their checks on: a small function (``SRC``), a pass
that breaks its IR and one that raises."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from kdsl.ir import Module
from kdsl.passes import ModulePass

SRC = """\
func.func @f(%x: f32) -> (f32) {kind = "func"} {
  %a = arith.constant {value = 2.0} : f32
  %b = arith.constant {value = 3.0} : f32
  %c = arith.mul %a, %b : f32
  %d = arith.add %x, %c : f32
  func.return %d
}
"""


@dataclass(frozen=True)
class BreakIRPass(ModulePass):
    """Moves the return to the top of the body: a use before its definition (invalid IR)."""

    name: ClassVar[str] = "break-ir"

    def apply(self, module: Module) -> bool:
        body = module.funcs[0].regions[0].block
        ret = body.ops[-1]
        body.detach(ret)
        body.insert(0, ret)  # the return now uses %d before it is defined
        return True


@dataclass(frozen=True)
class CrashPass(ModulePass):
    """Raises ZeroDivisionError."""

    name: ClassVar[str] = "crash"

    def apply(self, module: Module) -> bool:
        raise ZeroDivisionError("boom")
