"""AST pre-passes: which names a body assigns, and how a statement may exit.

They run before a body is lowered, so loops know their carried variables and the
frontend knows which statements need guarding (break/continue/return flags)
without visiting any body twice.
"""

from __future__ import annotations

import ast
from collections.abc import Callable

RETURN, BREAK, CONTINUE = "return", "break", "continue"


def _target_names(target: ast.expr, out: set[str]) -> None:
    """Names a target rebinds: ``x``, and the base of ``v[0]``/``v.x`` (a new SSA value)."""
    if isinstance(target, ast.Name):
        out.add(target.id)
    elif isinstance(target, ast.Tuple | ast.List):
        for elt in target.elts:
            _target_names(elt, out)
    elif isinstance(target, ast.Subscript | ast.Attribute | ast.Starred):
        _target_names(target.value, out)


class _Assigned(ast.NodeVisitor):
    def __init__(self) -> None:
        self.names: set[str] = set()

    def visit_Assign(self, node: ast.Assign) -> None:
        for t in node.targets:
            _target_names(t, self.names)

    def visit_AugAssign(self, node: ast.AugAssign) -> None:
        _target_names(node.target, self.names)

    def visit_AnnAssign(self, node: ast.AnnAssign) -> None:
        _target_names(node.target, self.names)

    def visit_For(self, node: ast.For) -> None:
        _target_names(node.target, self.names)
        if isinstance(node.iter, ast.Name):  # ``for i in query:`` advances the query in place
            self.names.add(node.iter.id)
        for s in node.body + node.orelse:
            self.visit(s)

    def visit_NamedExpr(self, node: ast.NamedExpr) -> None:
        _target_names(node.target, self.names)

    # Nested definitions are rejected elsewhere; their bodies assign nothing here.
    def visit_FunctionDef(self, node: ast.FunctionDef) -> None:
        pass

    visit_AsyncFunctionDef = visit_FunctionDef

    def visit_ClassDef(self, node: ast.ClassDef) -> None:
        pass

    def visit_Lambda(self, node: ast.Lambda) -> None:
        pass


def assigned_names(stmts: list[ast.stmt]) -> set[str]:
    """Every local name the statements (re)bind, at any nesting depth."""
    v = _Assigned()
    for s in stmts:
        v.visit(s)
    return v.names


def call_rebinds(nodes: list[ast.AST], positions: Callable[[ast.Call], set[int]]) -> set[str]:
    """Local names that calls with in-out parameters may rebind (``randf(state)``).

    ``positions(call)`` gives the argument positions the callee writes back
    (``inout.py``); a plain name passed there counts as assigned.
    """
    out: set[str] = set()
    for root in nodes:
        for node in ast.walk(root):
            if isinstance(node, ast.Call) and node.args:
                for k in positions(node):
                    if k < len(node.args) and isinstance(node.args[k], ast.Name):
                        out.add(node.args[k].id)
    return out


def exits(stmt: ast.stmt, in_loop: bool = True) -> set[str]:
    """The ways ``stmt`` may leave the code that follows it.

    ``break``/``continue`` count only when they belong to the enclosing loop (not
    to a loop nested inside ``stmt``); ``return`` counts at any depth.
    """
    if isinstance(stmt, ast.Return):
        return {RETURN}
    if isinstance(stmt, ast.Break):
        return {BREAK}
    if isinstance(stmt, ast.Continue):
        return {CONTINUE}
    out: set[str] = set()
    if isinstance(stmt, ast.If):
        for s in stmt.body + stmt.orelse:
            out |= exits(s)
    elif isinstance(stmt, ast.For | ast.While):
        for s in stmt.body + stmt.orelse:
            out |= exits(s) & {RETURN}
    return out


def body_exits(stmts: list[ast.stmt]) -> set[str]:
    """The union of ``exits`` over a statement list."""
    out: set[str] = set()
    for s in stmts:
        out |= exits(s)
    return out


def always_exits(stmts: list[ast.stmt]) -> bool:
    """True when every path through ``stmts`` ends in return/break/continue."""
    for s in stmts:
        if isinstance(s, ast.Return | ast.Break | ast.Continue):
            return True
        if isinstance(s, ast.If) and always_exits(s.body) and always_exits(s.orelse):
            return True
    return False


def always_returns(stmts: list[ast.stmt]) -> bool:
    """True when every path through ``stmts`` ends in a ``return``."""
    for s in stmts:
        if isinstance(s, ast.Return):
            return True
        if isinstance(s, ast.If) and always_returns(s.body) and always_returns(s.orelse):
            return True
    return False


def has_nontail_return(body: list[ast.stmt]) -> bool:
    """True when some ``return`` is not the last top-level statement of ``body``."""
    for i, s in enumerate(body):
        for node in ast.walk(s):
            if isinstance(node, ast.Return) and not (node is s and i == len(body) - 1):
                return True
    return False
