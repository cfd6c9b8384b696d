"""Custom gradients and replay functions: ``@kdsl.func_grad``, ``@kdsl.func_replay``.

Warp's API (``import kdsl as wp``)::

    @wp.func_grad(safe_sqrt)
    def adj_safe_sqrt(x: float, adj_ret: float):
        if x > 0.0:
            wp.adjoint[x] += 1.0 / (2.0 * wp.sqrt(x)) * adj_ret

A gradient function takes the primal function's parameters, then one adjoint per
result of the primal (``adj_ret``; one per element of a returned tuple). It returns
nothing: it adds to ``wp.adjoint[x]`` for parameters ``x`` (``+=``, ``=``, reads, a
struct field ``wp.adjoint[s.f]`` or a component ``wp.adjoint[v][0]`` too). A replay
function has the primal's signature and is what the backward pass's forward replay
runs instead of the primal.

IR contract (read by the ``adjoint`` pass):

- the primal's ``func.func`` carries ``custom_grad = "<grad symbol>"`` and, when a
  replay is given, ``custom_replay = "<replay symbol>"``; both functions are compiled
  into the module as ordinary ``kind = "func"`` functions whenever the primal is;
- the gradient function's parameters are ``(primal params..., adj_ret...)`` and it
  *returns* one value per primal parameter: that parameter's adjoint contribution,
  of the parameter's type. It starts at zero (the zero of the type for ints and
  bools too); an array parameter (which has no zero) is returned unchanged and
  carries no adjoint.

Lowering: each ``wp.adjoint[x]`` becomes a hidden local ``$adj:x`` (a rewrite of the
function's AST before it is lowered), so branches, loops and early ``return`` merge
the accumulators like any other variable, and every ``return`` returns them.
"""

from __future__ import annotations

import ast
import copy
import sys
from collections.abc import Callable
from functools import cached_property
from typing import TYPE_CHECKING, Any

from kdsl.errors import KdslError, KdslSyntaxError, KdslTypeError, source_line
from kdsl.frontend.analysis import always_returns
from kdsl.frontend.compiler import FunctionCompiler
from kdsl.frontend.inout import static_callee
from kdsl.frontend.kernel import CompileTarget, Function, Overload, unique_symbol
from kdsl.frontend.source import ParsedSource
from kdsl.ir import Loc, Operation
from kdsl.ir.types import MatrixType, ScalarType, StructType, Type, VectorType
from kdsl.ir.vjp import VjpContext

if TYPE_CHECKING:
    from kdsl.frontend.compiler import ModuleCompiler

#: Prefix of the hidden locals that hold ``wp.adjoint[x]`` in a gradient function.
ADJ_PREFIX = "$adj:"


class _Adjoint:
    """``kdsl.adjoint``: ``wp.adjoint[x]`` in a gradient function is ``x``'s adjoint."""

    #: What the frontend says when ``wp.adjoint`` appears outside a gradient function.
    __kdsl_misuse__ = (
        "wp.adjoint[...] can only be used inside a function decorated with @kdsl.func_grad(f)"
    )

    def __getitem__(self, key: Any) -> Any:
        raise KdslSyntaxError(self.__kdsl_misuse__)

    def __repr__(self) -> str:
        return "kdsl.adjoint"


adjoint = _Adjoint()


# --- decorators -------------------------------------------------------------------


def func_grad(primal: Function) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Register the decorated function as the gradient of one overload of ``primal``.

    The overload is the one whose parameter types begin the gradient function's;
    the remaining parameters (one adjoint per result of the primal) are checked when
    a kernel first compiles the primal. Returns the decorated function unchanged.
    """
    if not isinstance(primal, Function):
        raise _not_a_func(primal, "func_grad", _caller_loc())

    def register(fn: Callable[..., Any]) -> Callable[..., Any]:
        target = CustomTarget(fn, primal, "grad")
        types = target.arg_types()
        fits = [ov for ov in primal.overloads
                if len(ov.arg_types()) <= len(types)
                and ov.arg_types() == types[: len(ov.arg_types())]]  # fmt: skip
        if not fits:
            raise target.signature_error(
                f"gradient function '{target.name}' does not fit any overload of "
                f"{primal.name}(): its parameters must be the parameters of "
                f"{primal.name}() ({_signatures(primal)}) followed by one adjoint per result"
            )
        # With several fitting overloads the longest parameter list is the likely one.
        ov = max(fits, key=lambda o: len(o.arg_types()))
        target.primal = ov
        ov.custom_grad = target
        return fn

    return register


def func_replay(primal: Function) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Register the decorated function as what the backward pass replays for ``primal``.

    It must have the parameter types and results of one overload of ``primal``.
    Returns the decorated function unchanged.
    """
    if not isinstance(primal, Function):
        raise _not_a_func(primal, "func_replay", _caller_loc())

    def register(fn: Callable[..., Any]) -> Callable[..., Any]:
        target = CustomTarget(fn, primal, "replay")
        types = target.arg_types()
        fits = [ov for ov in primal.overloads if ov.arg_types() == types]
        if not fits:
            raise target.signature_error(
                f"replay function '{target.name}' must have the parameters of an overload "
                f"of {primal.name}() ({_signatures(primal)})"
            )
        target.primal = fits[0]
        fits[0].custom_replay = target
        return fn

    return register


def _not_a_func(primal: Any, deco: str, loc: Loc | None) -> KdslError:
    if getattr(primal, "__kdsl_kernel__", False):
        what = f"the kernel '{primal.name}'"
    elif callable(primal):
        what = f"the Python function {getattr(primal, '__name__', '?')!r}"
    else:
        what = f"a {type(primal).__name__}"
    return KdslTypeError(
        f"@kdsl.{deco}(f) needs a @kdsl.func as f, got {what} (write @kdsl.{deco}(my_func) "
        "above the new function's def)", loc,
    )  # fmt: skip


def _caller_loc() -> Loc | None:
    """The decorator line that called ``func_grad``/``func_replay`` (for errors)."""
    frame = sys._getframe(2)
    file, line = frame.f_code.co_filename, frame.f_lineno
    text = source_line(file, line)
    if text is None:
        return None
    col = len(text) - len(text.lstrip()) + 1
    return Loc(file, line, col, line, len(text.rstrip()) + 1)


def _signatures(fn: Function) -> str:
    return "; ".join("(" + ", ".join(map(str, ov.arg_types())) + ")" for ov in fn.overloads)


# --- the functions as compile targets ---------------------------------------------


class CustomTarget(CompileTarget):
    """A gradient (``role = "grad"``) or replay function of one primal overload."""

    def __init__(self, fn: Callable[..., Any], primal: Function, role: str) -> None:
        self.fn = fn
        self.name = fn.__name__
        self.role = role
        self.key = unique_symbol(fn, f"#{role}")
        #: The overload it belongs to (set when the decorator matches the signature).
        self.primal: Overload | None = None
        self.primal_fn = primal

    def signature_error(self, msg: str) -> KdslError:
        """A located error at the function's decorator (or its def)."""
        tree = self.src.tree
        node: ast.AST = next(
            (d for d in tree.decorator_list if f"func_{self.role}" in ast.unparse(d)), tree
        )
        return KdslTypeError(msg, self.src.loc(node), self.name)

    @cached_property
    def lowered_src(self) -> ParsedSource:
        """A gradient function's source with ``wp.adjoint`` rewritten (what is lowered)."""
        assert self.role == "grad" and self.primal is not None
        src = copy.copy(self.src)
        src.tree = _AdjointRewriter(self, len(self.primal.arg_types())).rewrite()
        return src


def has_zero(t: Type) -> bool:
    """True when ``t`` has a zero value an adjoint accumulator can start from."""
    if isinstance(t, ScalarType | VectorType | MatrixType):
        return True
    if isinstance(t, StructType):
        return all(has_zero(ft) for _, ft in t.fields)
    return False


class _AdjointRewriter(ast.NodeTransformer):
    """Turns ``wp.adjoint[p...]`` into the hidden local ``$adj:p`` and ``return`` into
    ``return $adj:a, $adj:b, ...`` (see the module docstring)."""

    def __init__(self, target: CustomTarget, n_primal: int) -> None:
        self.target = target
        self.src = target.src
        fdef = self.src.tree
        params = [a.arg for a in fdef.args.args]
        self.primal_params = params[:n_primal]
        self.adj_params = params[n_primal:]
        types = target.arg_types()[:n_primal]
        self.accumulated = {p for p, t in zip(self.primal_params, types) if has_zero(t)}
        # Names the function binds (a store into wp.adjoint[x] does not bind ``wp``).
        self.locals = set(params) | {
            n.id for n in ast.walk(fdef) if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Store)
        }
        self.scope = {**self.src.fn.__globals__, **self.src.closure_vars()}

    def error(self, msg: str, node: ast.AST) -> KdslError:
        return KdslSyntaxError(msg, self.src.loc(node), self.src.name)

    def rewrite(self) -> ast.FunctionDef:
        fdef = copy.deepcopy(self.src.tree)
        fdef.decorator_list = []
        body = [self.visit(s) for s in fdef.body]
        if not always_returns(body):
            last = body[-1] if body else fdef
            body.append(ast.copy_location(ast.Return(value=self.results(last)), last))
        fdef.body = body
        return fdef

    def results(self, at: ast.AST) -> ast.expr | None:
        names = [ADJ_PREFIX + p if p in self.accumulated else p for p in self.primal_params]
        elts = [ast.copy_location(ast.Name(id=n, ctx=ast.Load()), at) for n in names]
        if not elts:
            return None
        return elts[0] if len(elts) == 1 else ast.copy_location(ast.Tuple(elts, ast.Load()), at)

    def is_adjoint(self, node: ast.expr) -> bool:
        return static_callee(node, self.locals, self.scope) is adjoint

    def visit_Return(self, node: ast.Return) -> ast.Return:
        if node.value is not None:
            raise self.error(
                f"a gradient function returns nothing; add to the adjoints of "
                f"{self.target.primal_fn.name}()'s parameters with wp.adjoint[x] += ...", node
            )  # fmt: skip
        return ast.copy_location(ast.Return(value=self.results(node)), node)

    def visit_Subscript(self, node: ast.Subscript) -> ast.expr:
        if not self.is_adjoint(node.value):
            return self.generic_visit(node)
        path = self.visit(node.slice)  # indices inside the path may use wp.adjoint too
        root = path
        while isinstance(root, ast.Attribute | ast.Subscript):
            root = root.value
        if not isinstance(root, ast.Name):
            raise self.error("wp.adjoint[...] takes a parameter, a field of one (s.f) or a "
                             "component of one (v[0])", node.slice)  # fmt: skip
        name = root.id
        if name not in self.primal_params:
            what = "an adjoint input, not" if name in self.adj_params else "not"
            raise self.error(
                f"wp.adjoint[{name}]: '{name}' is {what} a parameter of "
                f"{self.target.primal_fn.name}(); wp.adjoint[...] takes one of "
                f"{', '.join(self.primal_params) or '(none)'}", root,
            )  # fmt: skip
        if name not in self.accumulated:
            raise self.error(f"wp.adjoint[{name}]: parameter '{name}' is an array (or holds "
                             "one); kdsl does not support adjoints of arrays in gradient "
                             "functions yet", root)  # fmt: skip
        new_root = ast.copy_location(ast.Name(id=ADJ_PREFIX + name, ctx=ast.Load()), root)
        if path is root:
            new_root.ctx = node.ctx
            return new_root
        parent = path
        while parent.value is not root:
            parent = parent.value
        parent.value = new_root
        path.ctx = node.ctx
        return path

    def visit_Name(self, node: ast.Name) -> ast.expr:
        if self.is_adjoint(node):
            raise self.error("wp.adjoint must be indexed with a parameter: wp.adjoint[x]", node)
        return node

    def visit_Attribute(self, node: ast.Attribute) -> ast.expr:
        if self.is_adjoint(node):
            raise self.error("wp.adjoint must be indexed with a parameter: wp.adjoint[x]", node)
        return self.generic_visit(node)


class GradCompiler(FunctionCompiler):
    """Lowers a gradient function; ``$adj:p`` accumulators start at zero."""

    def __init__(self, unit: ModuleCompiler, target: CustomTarget) -> None:
        super().__init__(unit, target, "func")
        self.src = target.lowered_src
        self._started = False

    def visit_body(self, stmts: list[ast.stmt]) -> None:
        if not self._started:  # the function's top-level body: set up the accumulators
            self._started = True
            target: CustomTarget = self.target
            assert target.primal is not None
            n = len(target.primal.arg_types())
            ctx = VjpContext(self.b, lambda v: v)
            with self.b.at(self.loc(self.src.tree)):
                for a, t in zip(self.src.tree.args.args[:n], target.arg_types()[:n]):
                    if has_zero(t):
                        self.vars[ADJ_PREFIX + a.arg] = ctx.zeros(t)
        super().visit_body(stmts)

    def assign_name(self, name: str, value: Any, node: ast.AST) -> None:
        old = self.vars.get(name)
        if name.startswith(ADJ_PREFIX) and old is not None:
            v = self.value(value, node, want=old.type) if not isinstance(value, tuple) else None
            if v is None or v.type != old.type:
                got = f"a {v.type}" if v is not None else "a tuple"
                raise self.error(
                    KdslTypeError, f"wp.adjoint[{name[len(ADJ_PREFIX):]}] is a {old.type} (the "
                    f"type of the parameter); cannot assign {got} to it", node)  # fmt: skip
            value = v
        super().assign_name(name, value, node)


def compile_custom(unit: ModuleCompiler, ov: Overload, func: Operation) -> None:
    """Compile ``ov``'s gradient and replay functions into ``unit`` and link them to the
    primal ``func`` through its ``custom_grad``/``custom_replay`` attributes."""
    for attr, target in (("custom_grad", ov.custom_grad), ("custom_replay", ov.custom_replay)):
        if target is None:
            continue
        done = unit.done.get(id(target))
        if done is None:
            try:
                done = _compile_target(unit, ov, func, target)
            except KdslError as e:
                raise e.add_context(
                    f"while compiling the {_ROLES[target.role]} function of '{ov.name}'"
                ) from None
            unit.done[id(target)] = done
        func.attrs[attr] = done.attrs["sym_name"]


_ROLES = {"grad": "gradient", "replay": "replay"}


def _compile_target(unit: ModuleCompiler, ov: Overload, func: Operation,
                    target: CustomTarget) -> Operation:  # fmt: skip
    n_inout = len(ov.inout_params())
    results = list(func.attrs["res_types"])
    if n_inout:
        raise target.signature_error(
            f"{ov.name}() has inout() parameters; kdsl does not support custom gradient or "
            "replay functions for such functions")  # fmt: skip
    params = ov.arg_types()
    types = target.arg_types()
    if target.role == "grad":
        want = params + results
        if types != want:
            names = [a.arg for a in ov.src.tree.args.args]
            names += ["adj_ret" if len(results) == 1 else f"adj_ret{k}"
                      for k in range(len(results))]  # fmt: skip
            sig = ", ".join(f"{n}: {t}" for n, t in zip(names, want))
            got = ", ".join(f"{a.arg}: {t}" for a, t in zip(target.src.tree.args.args, types))
            raise target.signature_error(
                f"gradient function '{target.name}' must take the parameters of {ov.name}() "
                f"then one adjoint per result: ({sig}); it takes ({got})")  # fmt: skip
        return GradCompiler(unit, target).compile(target.key, types)
    compiled = FunctionCompiler(unit, target, "func").compile(target.key, types)
    if list(compiled.attrs["res_types"]) != results:
        got = ", ".join(map(str, compiled.attrs["res_types"])) or "nothing"
        raise target.signature_error(
            f"replay function '{target.name}' must return what {ov.name}() returns "
            f"({', '.join(map(str, results)) or 'nothing'}), not ({got})")  # fmt: skip
    return compiled


__all__ = ["adjoint", "compile_custom", "func_grad", "func_replay"]
