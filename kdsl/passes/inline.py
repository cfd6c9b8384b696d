"""Inline every ``func.call`` to a ``kind = "func"`` function into its caller.

The callee's body is cloned before the call with its parameters bound to the call's
operands; the operands of its ``func.return`` replace the call's results. Callees
are inlined bottom-up (a callee is made call-free before it is copied), so nested
calls disappear in one run. Afterwards every ``kind = "func"`` function that no
kernel references any more is dropped (with ``drop_unused``).

Assumes the frontend's shape: a function has a single ``func.return``, the last op
of its body (early returns were turned into structured control flow). Recursion
cannot be inlined and raises ``KdslError`` at the call.

With ``keep_custom_grad``, calls to a function carrying ``custom_grad`` (a
``@kdsl.func_grad`` primal) stay calls, so the ``adjoint`` pass can call its
gradient function; everything else is still inlined. A function is dropped only
when no kernel reaches it through calls or through the ``custom_grad`` and
``custom_replay`` attributes of a function it reaches.

Each inlined op's location records the call it came through (``Loc.caller``), so an
error raised inside a library function also shows the caller's line.

Options: ``drop_unused`` (default true), ``keep_custom_grad`` (default false).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from kdsl.errors import KdslError
from kdsl.ir import Loc, Module, Operation, Value
from kdsl.ir.ops_func import CALL
from kdsl.ir.rewrite import clone_op, insert_before, replace_op
from kdsl.passes.manager import ModulePass


def _calls(func: Operation) -> list[Operation]:
    return [op for op in func.walk() if op.opdef is CALL]


def _inline_call(call: Operation, callee: Operation) -> None:
    body = callee.regions[0].block
    mapping: dict[Value, Value] = dict(zip(body.args, call.operands))
    seen: dict[int, Loc] = {}  # each callee location, seen through this call
    for op in body.ops[:-1]:
        new = clone_op(op, mapping)
        for inner in new.walk():
            loc = seen.get(id(inner.loc))
            if loc is None:
                loc = seen[id(inner.loc)] = inner.loc.called_from(call.loc)
            inner.loc = loc
        insert_before(call, new)
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
    #: Drop ``kind = "func"`` functions that no kernel reaches any more.
    drop_unused: bool = True
    #: Keep calls to functions with a custom gradient (for the ``adjoint`` pass).
    keep_custom_grad: bool = False

    def apply(self, module: Module) -> bool:
        changed = False
        for func in _order(module):
            for call in _calls(func):
                callee = module.get_func(call.attrs["callee"])
                if callee.attrs.get("kind") != "func":
                    continue
                if self.keep_custom_grad and callee.attrs.get("custom_grad"):
                    continue
                _inline_call(call, callee)
                changed = True
        if self.drop_unused:
            live = _reachable(module)
            for func in module.funcs:
                if func.attrs.get("kind") == "func" and func.attrs["sym_name"] not in live:
                    func.erase()
                    changed = True
        return changed


#: Function attributes that name another function the module must keep.
_REFERENCE_ATTRS = ("custom_grad", "custom_replay")


def _reachable(module: Module) -> set[str]:
    """Names of the functions reachable from the non-``func`` ones (kernels, adjoints)."""
    live: set[str] = set()
    work = [f for f in module.funcs if f.attrs.get("kind") != "func"]
    while work:
        func = work.pop()
        name = func.attrs["sym_name"]
        if name in live:
            continue
        live.add(name)
        refs = [op.attrs["callee"] for op in _calls(func)]
        refs += [func.attrs[a] for a in _REFERENCE_ATTRS if func.attrs.get(a)]
        work += [module.get_func(r) for r in refs if r not in live and module.has_func(r)]
    return live
