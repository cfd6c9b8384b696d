"""In-out parameters of ``@kdsl.func``: ``def randf(state: inout(uint32)) -> float``.

Warp's random functions advance their ``state`` argument in place (``uint32&`` in
its C++). kdsl values are immutable SSA values, so an in-out parameter is lowered
as an extra result instead:

- the callee returns its declared results followed by the final value of every
  in-out parameter (in parameter order); the IR sees an ordinary function;
- a call site whose argument at an in-out position is a plain local variable
  (``randf(state)``) rebinds that variable to the returned value; any other
  argument (a literal, ``arr[i]``, an expression) is read and not written back,
  as in Warp, where such an argument is a temporary;
- loops learn which variables such calls rebind from ``inout_positions`` before
  their body is lowered, so the rebinding is carried from one iteration to the
  next (``analysis.call_rebinds``).

Only functions that opt in have in-out parameters: a plain parameter stays a
by-value copy, so a user function that calls ``randf(state)`` on its own
parameter does not advance its caller's state (Warp behaves the same way).
"""

from __future__ import annotations

import ast
from types import ModuleType
from typing import Any


class InOut:
    """The annotation ``inout(T)``: a parameter of type ``T`` written back to the caller."""

    def __init__(self, t: Any) -> None:
        self.type = t

    def __repr__(self) -> str:
        return f"inout({getattr(self.type, '__name__', self.type)!s})"


def inout(t: Any) -> InOut:
    """Annotate a ``@kdsl.func`` parameter as in-out: the call rebinds the caller's variable."""
    return InOut(t)


def static_callee(node: ast.expr, local_names: set[str], scope: dict[str, Any]) -> Any:
    """The object a call's function expression names, resolved without lowering it.

    ``name`` (not shadowed by a local) and ``module.attr`` chains resolve; anything
    else gives None. Used by the loop pre-pass only, so it must have no effects.
    """
    if isinstance(node, ast.Name):
        return None if node.id in local_names else scope.get(node.id)
    if isinstance(node, ast.Attribute):
        base = static_callee(node.value, local_names, scope)
        if isinstance(base, ModuleType):
            return getattr(base, node.attr, None)
    return None


def inout_positions(fn: Any, nargs: int) -> set[int]:
    """Argument positions a call of ``fn`` with ``nargs`` arguments may write back.

    The union over ``fn``'s overloads that take ``nargs`` positional arguments (some
    parameters may keep their defaults): over-approximating only costs an unchanged
    loop-carried value.
    """
    out: set[int] = {p for p in getattr(fn, "inout", None) or () if p < nargs}  # builtins
    for ov in getattr(fn, "__kdsl_overloads__", None) or ():
        params = ov.inout_params()
        spec = ov.src.tree.args
        if params and len(spec.args) - len(spec.defaults) <= nargs <= len(spec.args):
            out.update(p for p in params if p < nargs)
    return out
