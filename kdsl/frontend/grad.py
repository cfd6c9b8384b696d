"""``kdsl.grad(f)``: the gradient of a function, called like the function (Warp's ``wp.grad``).

``wp.grad(f)(x, y)`` inside a kernel or function gives the derivative of ``f``'s result
at ``(x, y)`` with respect to each argument: one value when ``f`` takes one argument,
else a tuple (``dx, dy = wp.grad(f)(x, y)``). ``f`` is a ``@kdsl.func`` (its overload
picked by the arguments, as a call would) or a builtin (``wp.grad(wp.atan2)``). A
vector or matrix result is seeded with ones, as Warp does, so the gradient is that of
the sum of its components. Integer (and array) arguments get a zero.

The frontend lowers the call to a call of a gradient function it adds to the module:
``f``'s body, inlined, then reversed by the adjoint pass's machinery
(``kdsl.passes.adjoint.function_vjp``). Unlike Warp, where the call is forward-only (a
constant in the kernel's backward pass), a kernel's adjoint differentiates through it
(second derivatives). From Python, ``wp.grad(f)(0.5)`` evaluates the same IR on the
``interp`` backend (Warp raises there).
"""

from __future__ import annotations

import ast
import hashlib
from typing import Any

from kdsl.errors import KdslTypeError
from kdsl.frontend.builtins_base import Builtin
from kdsl.ir import Module, Operation, Value, new_func
from kdsl.ir.rewrite import clone_op
from kdsl.passes.adjoint.function_vjp import build_function_vjp
from kdsl.passes.inline import InlinePass


class GradOf:
    """``kdsl.grad(f)``: callable in kernels, functions and Python scope."""

    __kdsl_keywords__ = ()

    def __init__(self, fn: Any) -> None:
        if not (isinstance(fn, Builtin) or hasattr(fn, "__kdsl_overloads__")):
            raise KdslTypeError(
                f"grad() takes a @kdsl.func or a kernel builtin, not {type(fn).__name__}"
            )
        self.fn = fn
        self.name = self.__name__ = f"grad({fn.name})"

    # Equal for one ``f``: Python scope caches compiled calls by callee.
    def __eq__(self, other: object) -> bool:
        return isinstance(other, GradOf) and other.fn is self.fn

    def __hash__(self) -> int:
        return hash((GradOf, id(self.fn)))

    def __repr__(self) -> str:
        return f"kdsl.{self.name}"

    def __call__(self, *args: Any) -> Any:
        """The gradient at ``args``, evaluated in Python scope (see the module docstring)."""
        from kdsl.types import python_scope

        return python_scope(self, args)

    def lower_call(self, em: Any, args: list[Any], node: ast.Call, kwargs: dict) -> Any:
        """Lower ``grad(f)(args)`` in a kernel: a call of ``f``'s gradient function."""
        if kwargs:
            raise em.error(KdslTypeError, f"{self.name}() takes no keyword arguments", node)
        if isinstance(self.fn, Builtin):
            values = [em.value(a, node) for a in args]
            ident = self.fn.name
        else:
            overload, values = em.pick_overload(self.fn, args, node, {})
            ident = overload.key  # unique per function and overload
        module = em.unit.module
        # Named by f and the argument types, so a kernel's IR (and its cache key) does not
        # depend on compile order, and a second call with the same types reuses it.
        tag = hashlib.sha1(repr([str(v.type) for v in values]).encode()).hexdigest()[:8]
        sym = f"grad_{ident}_{tag}"
        if not module.has_func(sym):
            primal = self._primal(em, module, values, node, sym + "__primal")
            try:
                build_function_vjp(_inlined(module, primal), module, sym, self.name)
            finally:
                primal.erase()
        types = module.get_func(sym).attrs["res_types"]
        call = em.b.create("func.call", values, list(types), {"callee": sym}, loc=em.loc(node))
        results = list(call.results)
        return results[0] if len(results) == 1 else tuple(results)

    def _primal(
        self, em: Any, module: Module, values: list[Value], node: ast.Call, sym: str
    ) -> Operation:
        """``def sym(args): return f(args)``, compiled into ``module``."""
        types = [v.type for v in values]
        func = new_func(module, sym, types, [f"a{k}" for k in range(len(types))], [], "func",
                        em.loc(node))  # fmt: skip
        body = func.regions[0].block
        with em.b.at_end(body):
            r = em.call(self.fn, list(body.args), node)
            outs = [] if r is None else list(r) if isinstance(r, tuple) else [em.value(r, node)]
            if not outs:
                raise em.error(KdslTypeError, f"{self.name}: {self.fn.name}() returns nothing, "
                               "so it has no gradient", node)  # fmt: skip
            em.b.create("func.return", outs, loc=em.loc(node))
        func.attrs["res_types"] = [v.type for v in outs]
        return func


def _inlined(module: Module, func: Operation) -> Operation:
    """A call-free copy of ``func`` (in a scratch module holding copies of the functions)."""
    scratch = Module("grad")
    for f in module.funcs:
        if f.attrs.get("kind") == "func":  # the primal and whatever it may call
            scratch.add_func(clone_op(f, {}))
    InlinePass(drop_unused=False).apply(scratch)
    return scratch.get_func(func.attrs["sym_name"])


def grad(fn: Any) -> GradOf:
    """``grad(f)``: a callable giving the gradient of ``f``'s result with respect to each
    argument (Warp's ``wp.grad``; see ``kdsl.frontend.grad``)."""
    return GradOf(fn)


def _lower_grad(em: Any, args: list[Any], node: ast.Call, kwargs: dict) -> GradOf:
    # ``grad(f)`` inside a kernel: a compile-time object, called next.
    if len(args) != 1 or kwargs:
        raise em.error(KdslTypeError, "grad() takes one function", node)
    try:
        return GradOf(args[0])
    except KdslTypeError as e:
        raise em.error(KdslTypeError, str(e), node) from None


grad.lower_call = _lower_grad  # type: ignore[attr-defined]
