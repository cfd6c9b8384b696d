"""Compiling a kernel and the user functions it calls into one IR module."""

from __future__ import annotations

import ast
import builtins as pybuiltins
import inspect
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from kdsl.errors import KdslError, KdslSyntaxError, KdslTypeError
from kdsl.frontend.analysis import always_returns, has_nontail_return
from kdsl.frontend.bfloat16 import STORAGE_ONLY
from kdsl.frontend.control import RET
from kdsl.frontend.generic import Generic, generic_of
from kdsl.frontend.inout import InOut
from kdsl.frontend.statements import StatementLowering
from kdsl.frontend.values import describe, is_weak
from kdsl.ir import Module, Operation, Value, new_func
from kdsl.ir.types import BF16, BOOL, F32, I32, ScalarType, Type

if TYPE_CHECKING:
    from kdsl.frontend.kernel import Function, Overload


class FunctionCompiler(StatementLowering):
    """Lowers one Python function (kernel or ``@func`` overload) into a ``func.func``."""

    def __init__(self, unit: ModuleCompiler, target: Any, kind: str) -> None:
        super().__init__(target.src)
        self.unit = unit
        self.kind = kind
        self.target = target
        self.globals = {**target.src.fn.__globals__, **target.src.closure_vars()}

    def compile(self, sym_name: str, arg_types: list[Type]) -> Operation:
        fdef = self.src.tree
        if isinstance(fdef, ast.AsyncFunctionDef):
            raise self.error(KdslSyntaxError, "an async def cannot be a kernel or function", fdef)
        _check_signature(self, fdef)
        if self.kind == "kernel" and self.target.inout_params():
            raise self.error(KdslSyntaxError, "a kernel cannot have inout() parameters; "
                             "only a @kdsl.func writes one back to its caller", fdef)  # fmt: skip
        names = [a.arg for a in fdef.args.args]
        for name, t in zip(names, arg_types):
            if t is BF16:
                raise self.error(KdslTypeError, f"parameter '{name}': {STORAGE_ONLY}", fdef)
        func = new_func(self.unit.module, sym_name, arg_types, names, [], self.kind,
                        self.loc(fdef))  # fmt: skip
        body = func.regions[0].block
        for name, arg in zip(names, body.args):
            self.vars[name] = arg
        if self.kind == "func" and _returns_value(fdef) and not always_returns(fdef.body):
            raise self.error(
                KdslSyntaxError,
                f"function '{self.src.name}' may end without returning a value; every path "
                "must return",
                fdef,
            )
        with self.b.at_end(body):
            if has_nontail_return(fdef.body):
                self.vars[RET] = self.const(False, BOOL, fdef)
            self.visit_body(fdef.body)
            res = self.res_types or []
            rv = [self.vars[f"$rv{k}"] for k in range(len(res))]
            # In-out parameters come back after the declared results (see inout.py).
            inout = [self.vars[names[k]] for k in self.target.inout_params()]
            end = fdef.body[-1] if fdef.body else fdef
            self.b.create("func.return", rv + inout, loc=self.loc(end))
        func.attrs["res_types"] = list(res) + [v.type for v in inout]
        return func

    def call_user(
        self, fn: Function, args: list[Any], node: ast.Call, kwargs: dict | None = None
    ) -> Any:
        """A call of a ``@kdsl.func``: pick the overload, compile it once, ``func.call``."""
        overload, values = self.pick_overload(fn, args, node, kwargs or {})
        callee = self.unit.compile_func(overload, self, node)
        res = callee.attrs["res_types"]
        op = self.b.create("func.call", values, list(res), {"callee": callee.attrs["sym_name"]},
                           loc=self.loc(node))  # fmt: skip
        results = list(op.results)
        inout = overload.inout_params()
        if inout:
            results, written = results[: len(results) - len(inout)], results[-len(inout) :]
            self.write_back(inout, written, args, node)
        if not results:
            return None
        return results[0] if len(results) == 1 else tuple(results)

    def write_back(self, positions, written: list[Value], args: list[Any], node: ast.Call) -> None:
        """Rebind each local variable passed at an in-out position to its new value.

        Only a plain local name whose current value is the one passed is rebound;
        other arguments are temporaries (see ``inout.py``).
        """
        for k, new in zip(positions, written):
            arg = node.args[k] if k < len(node.args) else None
            if isinstance(arg, ast.Name) and self.vars.get(arg.id) is args[k]:
                self.bind_raw(arg.id, new)

    def pick_overload(self, fn: Function, args: list[Any], node: ast.Call, kwargs: dict):
        """The overload a call runs and its argument values (Warp's rules).

        Keywords and default values fill in each overload's parameter list first.
        Overloads whose parameter types are all concrete win over generic ones (``Any``,
        ``array(dtype=Any)``); among each, an exact match wins over one that converts
        a literal. A generic overload is instantiated for the arguments' types.
        """
        for a in [*args, *kwargs.values()]:
            if not (isinstance(a, Value) or is_weak(a)):
                raise self.error(KdslTypeError, f"cannot pass {describe(a)} to {fn.name}()", node)
        candidates, reasons = [], []
        for ov in fn.overloads:
            bound = _bind(ov, args, kwargs)
            if isinstance(bound, str):
                reasons.append(bound)
                continue
            bound = [self.default_value(ov, a, node) if _is_default(a) else a for a in bound]
            types = ov.arg_types()
            score = _match(bound, types)
            if score is not None:
                candidates.append((score, len(candidates), ov, bound))
        if not candidates:
            if len(fn.overloads) == 1 and reasons:
                raise self.error(KdslTypeError, f"{fn.name}() {reasons[0]}", node)
            got = ", ".join(str(a.type) if isinstance(a, Value) else repr(a) for a in args)
            got += "".join(f", {k}=" + (str(v.type) if isinstance(v, Value) else repr(v))
                           for k, v in kwargs.items())  # fmt: skip
            sigs = "; ".join("(" + ", ".join(map(str, ov.arg_types())) + ")"
                             for ov in fn.overloads)  # fmt: skip
            raise self.error(
                KdslTypeError, f"no overload of {fn.name}() takes ({got}); it takes: {sigs}", node
            )
        candidates.sort(key=lambda c: c[:2])
        _, _, ov, bound = candidates[0]
        types = ov.arg_types()
        if any(isinstance(t, Generic) for t in types):
            concrete = [_arg_type(a) if isinstance(t, Generic) else t for a, t in zip(bound, types)]
            ov = ov.instance(concrete)
            types = concrete
        values = [self.value(a, node, want=t) for a, t in zip(bound, types)]
        return ov, values

    def default_value(self, ov: Any, d: _Default, node: ast.AST) -> Any:
        v = self.python_value(d.value, node)
        if not (isinstance(v, Value) or is_weak(v)):
            raise self.error(KdslTypeError, f"{ov.name}(): the default value of '{d.name}' "
                             f"is {describe(d.value)}, not a number or vector", node)  # fmt: skip
        return v


class _Default:
    """A parameter's default value, used where a call leaves it out."""

    __slots__ = ("name", "value")

    def __init__(self, name: str, value: Any) -> None:
        self.name = name
        self.value = value


def _is_default(a: Any) -> bool:
    return isinstance(a, _Default)


def _bind(ov: Any, args: list[Any], kwargs: dict) -> list[Any] | str:
    """``args`` and ``kwargs`` in ``ov``'s parameter order, defaults filled in; or why not."""
    params = [a.arg for a in ov.src.tree.args.args]
    defaults = ov.fn.__defaults__ or ()
    if len(args) > len(params):
        return f"takes {len(params)} arguments, got {len(args)}"
    out: list[Any] = list(args)
    for k, name in enumerate(params[len(args) :], len(args)):
        if name in kwargs:
            out.append(kwargs[name])
            continue
        d = k - (len(params) - len(defaults))
        if d < 0:
            return f"missing argument '{name}' (it takes {', '.join(params)})"
        out.append(_Default(name, defaults[d]))
    for name in kwargs:
        if name not in params:
            return f"has no parameter '{name}' (it takes {', '.join(params)})"
        if params.index(name) < len(args):
            return f"got two values for '{name}'"
    return out


def _arg_type(a: Any) -> Type:
    """The type a generic parameter takes for argument ``a`` (a literal: Warp's defaults)."""
    if isinstance(a, Value):
        return a.type
    return BOOL if isinstance(a, bool) else I32 if isinstance(a, int) else F32


def _match(args: list[Any], types: list[Any]) -> tuple[int, int] | None:
    """How well ``args`` fit ``types``, best first; None if they do not.

    (literals converted from their own type, generic parameters): as in Warp, an
    exact match wins, then a generic instance; kdsl also converts a literal (``7``
    to a float parameter) where nothing else fits.
    """
    generic = score = 0
    for a, t in zip(args, types):
        if isinstance(t, Generic):
            generic += 1
            if not t.matches(_arg_type(a)):
                return None
        elif isinstance(a, Value):
            if a.type != t:
                return None
        elif isinstance(t, ScalarType):
            if isinstance(a, bool) != t.is_bool or (isinstance(a, float) and not t.is_float):
                return None
            score += _arg_type(a) != t
        else:
            return None
    return score, generic


def _returns_value(fdef: ast.FunctionDef) -> bool:
    return any(isinstance(n, ast.Return) and n.value is not None for n in ast.walk(fdef))


def _check_signature(em: FunctionCompiler, fdef: ast.FunctionDef) -> None:
    a = fdef.args
    extra = a.vararg or a.kwarg or a.kwonlyargs or a.posonlyargs
    if extra:
        raise em.error(KdslSyntaxError, "kernel and function parameters must be plain "
                       "annotated names (no *args, **kwargs)", fdef)  # fmt: skip
    if a.defaults and em.kind == "kernel":
        raise em.error(KdslSyntaxError, "kernel parameters cannot have default values (launch "
                       "passes every argument); a @kdsl.func's can", a.defaults[0])  # fmt: skip
    for node in ast.walk(fdef):
        if node is not fdef and isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef |
                                           ast.ClassDef | ast.Lambda):  # fmt: skip
            raise em.error(KdslSyntaxError, f"{_what(node)} cannot be defined inside a kernel "
                           "or function", node)  # fmt: skip


def _what(node: ast.AST) -> str:
    return {"ClassDef": "a class", "Lambda": "a lambda"}.get(type(node).__name__, "a function")


class ModuleCompiler:
    """One build: the module, compiled overloads, and the call stack (for recursion)."""

    def __init__(self, name: str) -> None:
        self.module = Module(name)
        self.done: dict[int, Operation] = {}
        self.stack: list[Overload] = []

    def compile_func(self, ov: Overload, caller: FunctionCompiler, node: ast.AST) -> Operation:
        if ov in self.stack:
            chain = " -> ".join(o.name for o in [*self.stack, ov])
            raise caller.error(KdslSyntaxError, f"recursion is not supported ({chain})", node)
        if id(ov) in self.done:
            return self.done[id(ov)]
        self.stack.append(ov)
        try:
            fc = FunctionCompiler(self, ov, "func")
            func = fc.compile(ov.key, ov.arg_types())
        finally:
            self.stack.pop()
        self.done[id(ov)] = func
        if ov.custom_grad is not None or ov.custom_replay is not None:
            from kdsl.frontend.custom_grad import compile_custom

            compile_custom(self, ov, func)
        return func


def annotation_types(fn: Any, names: Sequence[str]) -> list[Type] | None:
    """The IR types of the annotations of ``fn``'s parameters ``names``, resolved as
    ``resolve_annotation`` resolves them but without the function's source; None where
    one would raise (``resolve_annotation`` then says where)."""
    from kdsl.types import type_of

    anns = fn.__annotations__
    scope: dict[str, Any] | None = None
    out: list[Type] = []
    for name in names:
        ann = anns.get(name)
        if ann is None:
            return None
        if isinstance(ann, str):
            try:
                scope = scope if scope is not None else annotation_scope(fn)
                ann = eval(ann, scope)
            except Exception:
                return None
        if isinstance(ann, InOut):
            ann = ann.type
        generic = generic_of(ann)
        if generic is not None:
            out.append(generic)  # type: ignore[arg-type]
            continue
        try:
            out.append(type_of(ann))
        except (TypeError, KdslError):
            return None
    return out


def annotation_scope(fn: Any) -> dict[str, Any]:
    """The names a string annotation of ``fn`` is evaluated with: Python's builtins, the
    function's globals, then its closure (a kernel factory's dtype lives there)."""
    return {**vars(pybuiltins), **fn.__globals__, **inspect.getclosurevars(fn).nonlocals}


def resolve_annotation(target: Any, name: str, ann: Any, node: ast.AST | None) -> Type:
    """The IR type of a parameter annotation, or a located KdslTypeError."""
    from kdsl.types import type_of

    src = target.src
    if ann is None:
        raise KdslTypeError(
            f"parameter '{name}' of {src.name} needs a type annotation (e.g. {name}: float)",
            src.loc(node), src.name,
        )  # fmt: skip
    ann = evaluate_annotation(target, name, ann, node)
    if isinstance(ann, InOut):
        ann = ann.type
    generic = generic_of(ann)
    if generic is not None:
        return generic  # type: ignore[return-value]  # filled in per call or launch
    try:
        return type_of(ann)
    except (TypeError, KdslError):
        raise KdslTypeError(
            f"the annotation of '{name}' is not a kdsl type: {ann!r} (expected float, int, "
            "wp.vec3, wp.array(dtype=...), ...)", src.loc(node), src.name,
        ) from None  # fmt: skip


def evaluate_annotation(target: Any, name: str, ann: Any, node: ast.AST | None) -> Any:
    """A parameter annotation as an object (a string annotation is evaluated)."""
    src = target.src
    if isinstance(ann, str):
        try:
            ann = eval(ann, annotation_scope(src.fn))
        except Exception:
            raise KdslTypeError(f"cannot resolve the annotation {ann!r} of '{name}'",
                                src.loc(node), src.name) from None  # fmt: skip
    return ann
