"""Inline every ``func.call`` to a ``kind = "func"`` function into its caller.

The callee's body is cloned before the call with its parameters bound to the call's
operands; the operands of its ``func.return`` replace the call's results. Callees
are inlined bottom-up (a callee is made call-free before it is copied), so nested
calls disappear in one run. Afterwards every ``kind = "func"`` function that no
kernel references any more is dropped (with ``drop_unused``).

Assumes the frontend's shape: a function has a single ``func.return``, the last op
of its body (early returns were turned into structured control flow). Recursion
cannot be inlined and raises ``KdslError`` at the call.

Options: ``drop_unused`` (default true).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from kdsl.errors import KdslError
from kdsl.ir import Module, Operation, Value
from kdsl.passes._rewrite import clone_op, insert_before, replace_op
from kdsl.passes.manager import ModulePass


def _calls(func: Operation) -> list[Operation]:
    return [op for op in func.walk() if op.name == "func.call"]


def _inline_call(call: Operation, callee: Operation) -> None:
    body = callee.regions[0].block
    mapping: dict[Value, Value] = dict(zip(body.args, call.operands))
    for op in body.ops[:-1]:
        insert_before(call, clone_op(op, mapping))
    ret = body.ops[-1]
    replace_op(call, [mapping.get(v, v) for v in ret.operands])


def _order(module: Module) -> list[Operation]:
    """Functions with every callee before its callers; raises on recursion."""
    done: dict[str, Operation] = {}
    active: set[str] = set()

    def visit(func: Operation) -> None:
        name = func.attrs["sym_name"]
        if name in done:
            return
        active.add(name)
        for call in _calls(func):
            callee = call.attrs["callee"]
            if callee in active:
                raise KdslError(f"recursive call to {callee}() cannot be inlined", call.loc)
            visit(module.get_func(callee))
        active.discard(name)
        done[name] = func

    for func in module.funcs:
        visit(func)
    return list(done.values())


@dataclass(frozen=True)
class InlinePass(ModulePass):
    """Inline function calls (see the module docstring)."""

    name: ClassVar[str] = "inline"
    #: Drop ``kind = "func"`` functions that nothing calls any more.
    drop_unused: bool = True

    def apply(self, module: Module) -> bool:
        changed = False
        for func in _order(module):
            for call in _calls(func):
                callee = module.get_func(call.attrs["callee"])
                if callee.attrs.get("kind") != "func":
                    continue
                _inline_call(call, callee)
                changed = True
        if self.drop_unused:
            for func in module.funcs:
                if func.attrs.get("kind") == "func" and not self._referenced(module, func):
                    func.erase()
                    changed = True
        return changed

    @staticmethod
    def _referenced(module: Module, func: Operation) -> bool:
        name = func.attrs["sym_name"]
        return any(
            op.name == "func.call" and op.attrs["callee"] == name
            for other in module.funcs
            if other is not func
            for op in other.walk()
        )
