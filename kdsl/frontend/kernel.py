"""``@kdsl.kernel`` and ``@kdsl.func``: the objects users decorate functions into."""

from __future__ import annotations

import copy
import hashlib
import inspect
import weakref
from collections.abc import Callable
from functools import cached_property
from typing import Any

from kdsl.errors import KdslError, KdslTypeError, full_tracebacks
from kdsl.frontend.fingerprint import SourceMemo, source_fingerprint
from kdsl.frontend.generic import Generic, is_generic
from kdsl.frontend.source import ParsedSource
from kdsl.frontend.structs import register_structs
from kdsl.ir import Module, verify_module
from kdsl.ir.types import Type


def unique_symbol(fn: Callable[..., Any], extra: str = "") -> str:
    """A unique, readable symbol for ``fn``: its name plus a short hash of where it is
    defined (and of ``extra``, which tells apart several targets of one function)."""
    where = f"{fn.__module__}.{fn.__qualname__}:{fn.__code__.co_firstlineno}{extra}"
    digest = hashlib.sha1(where.encode()).hexdigest()[:8]
    return f"{fn.__name__}_{digest}"


class CompileTarget:
    """A Python function the frontend compiles: its parsed source and parameter types.

    The base of kernels, ``@kdsl.func`` overloads and custom gradient and replay
    functions (``custom_grad.CustomTarget``); a subclass sets ``fn``.
    """

    fn: Callable[..., Any]

    @cached_property
    def src(self) -> ParsedSource:
        return ParsedSource(self.fn)

    def arg_types(self) -> list[Type]:
        if not hasattr(self, "_arg_types"):
            from kdsl.frontend.compiler import annotation_types, resolve_annotation

            # Plain parameters: resolved without the source (a warm start never parses
            # it); the source only to locate what is wrong.
            params = _plain_params(self.fn)
            fast = annotation_types(self.fn, params) if params else None
            if fast is not None:
                self._arg_types = fast
            else:
                args = self.src.tree.args.args
                anns = self.fn.__annotations__
                self._arg_types = [
                    resolve_annotation(self, a.arg, anns.get(a.arg), a) for a in args
                ]
        return self._arg_types

    @property
    def is_generic(self) -> bool:
        """True when a parameter is ``Any`` or an array of ``dtype=Any`` (see ``generic.py``)."""
        g = self.__dict__.get("_generic")
        if g is None:
            g = self.__dict__["_generic"] = is_generic(
                _trimmed(lambda: CompileTarget.arg_types(self))
            )
        return g

    def instance(self, types: list[Type]) -> Any:
        """This generic target with concrete parameter ``types``, made once per tuple.

        Raises a located KdslTypeError when ``types`` do not fit the parameters.
        """
        types = list(types)
        key = tuple(types)
        cache = self.__dict__.setdefault("_instances", {})
        inst = cache.get(key)
        if inst is not None:
            return inst
        params = CompileTarget.arg_types(self)
        names = [a.arg for a in self.src.tree.args.args]
        if len(types) != len(params):
            raise KdslTypeError(f"{self.name} takes {len(params)} parameters, got {len(types)} "
                                "types", self.src.loc(self.src.tree), self.src.name)  # fmt: skip
        for name, want, got in zip(names, params, types):
            ok = want.matches(got) if isinstance(want, Generic) else want == got
            if not ok:
                raise KdslTypeError(
                    f"{self.name}: parameter '{name}' is {want}, which a {got} does not fit",
                    self.src.loc(self.src.tree), self.src.name,
                )  # fmt: skip
        inst = copy.copy(self)
        for attr in ("_instances", "_kdsl_compiled", "_kdsl_plans", "_generic"):
            inst.__dict__.pop(attr, None)
        inst._arg_types = types
        inst.key = f"{self.key}_{hashlib.sha1(repr(key).encode()).hexdigest()[:8]}"
        inst.generic = self
        cache[key] = inst
        return inst

    def instances(self) -> list[Any]:
        """The instances made so far (declared with ``kdsl.overload`` or at calls/launches)."""
        return list(self.__dict__.get("_instances", {}).values())

    def declared_instances(self) -> list[Any]:
        """The instances declared with ``kdsl.overload``."""
        return [i for i in self.instances() if i.__dict__.get("declared")]

    def inout_params(self) -> tuple[int, ...]:
        """Indices of the parameters annotated ``inout(T)`` (see ``inout.py``)."""
        if not hasattr(self, "_inout"):
            from kdsl.frontend.compiler import evaluate_annotation
            from kdsl.frontend.inout import InOut

            args = self.src.tree.args.args
            anns = self.fn.__annotations__
            self._inout = tuple(
                k for k, a in enumerate(args)
                if isinstance(evaluate_annotation(self, a.arg, anns.get(a.arg), a), InOut)
            )  # fmt: skip
        return self._inout


def _plain_params(fn: Callable[..., Any]) -> tuple[str, ...]:
    """The parameter names of ``fn`` when they are all plain positional ones (what the
    frontend's ``args.args`` lists), else ``()`` (the caller then reads the source)."""
    code = getattr(fn, "__code__", None)
    if code is None or code.co_posonlyargcount or code.co_kwonlyargcount:
        return ()
    if code.co_flags & (inspect.CO_VARARGS | inspect.CO_VARKEYWORDS):
        return ()
    return code.co_varnames[: code.co_argcount]


class Kernel(CompileTarget):
    """A compiled-on-demand kernel. Launch it with ``kdsl.launch``.

    Attributes: ``name``, ``key`` (its unique symbol in IR modules), ``arg_names``,
    ``arg_types`` (IR types), ``tid_ndim`` (how many dims ``tid()`` unpacks into),
    ``source_file``, ``options``, ``module`` (the Python module name).
    """

    __kdsl_kernel__ = True

    def __init__(self, fn: Callable[..., Any], **options: Any) -> None:
        self.fn = fn
        self.func = fn
        self.name = fn.__name__
        self.key = unique_symbol(fn)
        self.module = fn.__module__
        self.options = dict(options)  # its module's options fill in the rest (runtime.modules)
        self.arg_names = list(inspect.signature(fn).parameters)
        self.source_file = inspect.getsourcefile(fn) or fn.__code__.co_filename
        self._tid_ndim: int | None = None
        self.__doc__ = fn.__doc__
        self.__name__ = fn.__name__
        _KERNELS.setdefault(self.module, weakref.WeakValueDictionary())[id(self)] = self

    @property
    def arg_types(self) -> list[Type]:  # type: ignore[override]
        return _trimmed(lambda: CompileTarget.arg_types(self))

    @property
    def tid_ndim(self) -> int:
        """Number of dimensions ``tid()`` is unpacked into (1 when it is not used)."""
        if self._tid_ndim is None:
            self.build_module()
        return self._tid_ndim or 1

    def build_module(self) -> Module:
        """A fresh, verified, unoptimized module: this kernel plus the funcs it calls."""
        return _trimmed(self._build)

    def source_fingerprint(self, memo: SourceMemo | None = None) -> str | None:
        """The digest of everything ``build_module`` reads (``kdsl.frontend.fingerprint``),
        or None when it cannot be known without building (the cache then keys the IR).
        ``memo`` holds recorded source facts (read without parsing) and gets new ones."""
        return None if self.is_generic else source_fingerprint(self, memo)

    def build_facts(self) -> dict[str, Any]:
        """What the last ``build_module`` learnt that launches need (``tid_ndim``)."""
        return {"tid_ndim": self._tid_ndim}

    def restore_build_facts(self, facts: dict[str, Any]) -> None:
        """Take ``build_facts`` of an earlier build of this same source (a cache hit)."""
        if self._tid_ndim is None:
            self._tid_ndim = facts.get("tid_ndim")

    def _build(self) -> Module:
        from kdsl.frontend.compiler import FunctionCompiler, ModuleCompiler

        if self.is_generic:
            raise KdslTypeError(
                f"kernel '{self.name}' is generic (it has Any parameters): launch it, which "
                "compiles it for the arguments' types, or declare an instance with "
                "kdsl.overload(kernel, [types...])", self.src.loc(self.src.tree), self.src.name,
            )  # fmt: skip
        unit = ModuleCompiler(self.key)
        fc = FunctionCompiler(unit, self, "kernel")
        try:
            func = fc.compile(self.key, CompileTarget.arg_types(self))
        except KdslError as e:
            raise e.add_context(f"while compiling kernel '{self.name}'") from None
        # The kernel goes first, then the functions in the order they were compiled.
        unit.module.body.ops.remove(func)
        unit.module.body.ops.insert(0, func)
        register_structs(unit.module)
        verify_module(unit.module)
        self._tid_ndim = fc.tid_ndim or 1
        return unit.module

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        raise KdslError(
            f"kernel '{self.name}' cannot be called directly from Python; launch it with "
            f"kdsl.launch({self.name}, dim=..., inputs=[...])"
        )

    def __repr__(self) -> str:
        return f"<kdsl.Kernel {self.name}>"


class Overload(CompileTarget):
    """One signature of a ``@kdsl.func``.

    ``custom_grad``/``custom_replay``: its ``@kdsl.func_grad``/``@kdsl.func_replay``
    functions (``custom_grad.CustomTarget``), or None.
    """

    def __init__(self, fn: Callable[..., Any], index: int) -> None:
        self.fn = fn
        self.name = fn.__name__
        self.key = unique_symbol(fn, f"#{index}")
        self.custom_grad: Any = None
        self.custom_replay: Any = None


class Function:
    """A ``@kdsl.func``: one or more overloads picked by argument types at each call."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.__name__ = name
        self.overloads: list[Overload] = []

    @property
    def __kdsl_overloads__(self) -> list[Overload]:
        return self.overloads

    def add(self, fn: Callable[..., Any]) -> None:
        sig = _annotation_key(fn)
        self.overloads = [o for o in self.overloads if _annotation_key(o.fn) != sig]
        self.overloads.append(Overload(fn, len(self.overloads)))

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        # In Python scope a standard-library function is a builtin (kernel semantics, as
        # in Warp); a user's runs as plain Python (its first overload of that arity).
        if self.overloads and self.overloads[0].fn.__module__.startswith("kdsl."):
            from kdsl.types import python_scope

            return python_scope(self, args, kwargs)
        for ov in self.overloads:
            try:
                inspect.signature(ov.fn).bind(*args, **kwargs)  # defaults and keywords too
            except TypeError:
                continue
            return ov.fn(*args, **kwargs)
        raise TypeError(f"{self.name}() has no overload taking {len(args)} arguments")

    def __repr__(self) -> str:
        return f"<kdsl.Function {self.name} ({len(self.overloads)} overloads)>"


def _annotation_key(fn: Callable[..., Any]) -> tuple:
    return tuple(repr(v) for k, v in fn.__annotations__.items() if k != "return")


_FUNCTIONS: dict[tuple[str, str], Function] = {}
#: The live kernels of each Python module, by id, in definition order (Warp's modules).
_KERNELS: dict[str, weakref.WeakValueDictionary] = {}


def kernels_of_module(name: str) -> list[Kernel]:
    """The live kernels defined in the Python module ``name``, in definition order."""
    entries = _KERNELS.get(name)
    return list(entries.values()) if entries is not None else []


def modules_with_kernels() -> list[str]:
    """The names of the Python modules that define live kernels."""
    return [n for n, e in _KERNELS.items() if len(e)]


def func(fn: Callable[..., Any]) -> Function:
    """Decorate a kernel-language function. Several definitions with one name and
    different annotations are overloads; calls pick one by argument types."""
    key = (fn.__module__, fn.__qualname__)
    f = _FUNCTIONS.get(key)
    if f is None:
        f = _FUNCTIONS[key] = Function(fn.__name__)
    f.add(fn)
    return f


def kernel(fn: Callable[..., Any] | None = None, **options: Any) -> Any:
    """Decorate a kernel: ``@kdsl.kernel`` or ``@kdsl.kernel(enable_backward=False)``."""
    if fn is None:
        return lambda f: Kernel(f, **options)
    return Kernel(fn, **options)


def overload(kernel: Any, arg_types: list[Any] | dict[str, Any] | None = None) -> Kernel:
    """Declare the instance of a generic kernel for concrete types (Warp's ``wp.overload``).

    ``kdsl.overload(k, [t0, t1, ...])`` gives every parameter's type;
    ``kdsl.overload(k, {"name": t})`` the generic ones by name (the others keep their
    declared types). As a decorator, ``@kdsl.overload`` on a stub ``def`` with the
    kernel's name and concrete annotations declares that instance. Returns the
    instance, a kernel that ``kdsl.launch`` runs like any other.
    """
    from kdsl.types import type_of

    if not isinstance(kernel, Kernel):
        if not inspect.isfunction(kernel):
            raise KdslTypeError(f"kdsl.overload() takes a generic kernel, not {kernel!r}")
        stub = kernel
        found = [k for k in kernels_of_module(stub.__module__)
                 if k.fn.__qualname__ == stub.__qualname__]  # fmt: skip
        if not found:
            raise KdslTypeError(f"@kdsl.overload: no kernel named '{stub.__name__}' in module "
                                f"{stub.__module__} (define the generic kernel first)")  # fmt: skip
        kernel, arg_types = found[-1], _stub_types(found[-1], stub)
    if not kernel.is_generic:
        raise KdslTypeError(f"kdsl.overload(): kernel '{kernel.name}' is not generic (it has no "
                            "Any parameter); launch it as it is")  # fmt: skip
    declared = CompileTarget.arg_types(kernel)
    if isinstance(arg_types, dict):
        types: list[Any] = list(declared)
        for name, t in arg_types.items():
            if name not in kernel.arg_names:
                raise KdslTypeError(f"kdsl.overload(): kernel '{kernel.name}' has no parameter "
                                    f"'{name}' (it has {', '.join(kernel.arg_names)})")  # fmt: skip
            types[kernel.arg_names.index(name)] = t
    elif isinstance(arg_types, list | tuple):
        types = list(arg_types)
    else:
        raise KdslTypeError("kdsl.overload(kernel, arg_types): arg_types must be a list of "
                            f"types or a dict of name: type, not {arg_types!r}")  # fmt: skip
    concrete = []
    for k, t in enumerate(types):
        if isinstance(t, Generic | Type):
            concrete.append(t)
            continue
        try:
            concrete.append(type_of(t))
        except (TypeError, KdslError):
            name = kernel.arg_names[k] if k < len(kernel.arg_names) else str(k)
            raise KdslTypeError(f"kdsl.overload(): the type of '{name}' for kernel "
                                f"'{kernel.name}' is not a concrete kdsl type: {t!r}") from None  # fmt: skip
    for name, t in zip(kernel.arg_names, concrete):
        if isinstance(t, Generic):
            raise KdslTypeError(f"kdsl.overload(): parameter '{name}' of kernel '{kernel.name}' "
                                f"needs a concrete type (it is {t})")  # fmt: skip
    inst = _trimmed(lambda: kernel.instance(concrete))
    inst.declared = True
    return inst


def _stub_types(kernel: Kernel, stub: Callable[..., Any]) -> list[Any]:
    names = list(inspect.signature(stub).parameters)
    if names != kernel.arg_names:
        raise KdslTypeError(f"@kdsl.overload of '{kernel.name}': the stub's parameters "
                            f"({', '.join(names)}) differ from the kernel's "
                            f"({', '.join(kernel.arg_names)})")  # fmt: skip
    anns = dict(stub.__annotations__)
    for n, a in anns.items():
        if isinstance(a, str):  # from __future__ import annotations
            try:
                anns[n] = eval(a, stub.__globals__)
            except Exception:
                raise KdslTypeError(f"@kdsl.overload of '{kernel.name}': cannot resolve the "
                                    f"annotation {a!r} of '{n}'") from None  # fmt: skip
    missing = [n for n in names if n not in anns]
    if missing:
        raise KdslTypeError(f"@kdsl.overload of '{kernel.name}': annotate every parameter "
                            f"(missing: {', '.join(missing)})")  # fmt: skip
    return [anns[n] for n in names]


def _trimmed(fn: Callable[[], Any]) -> Any:
    """Run ``fn``; a KdslError leaves without the compiler's internal frames.

    ``KDSL_TRACEBACK`` is read only when an error leaves (launches ask for a kernel's
    argument types on every call).
    """
    try:
        return fn()
    except KdslError as e:
        if full_tracebacks():
            raise
        err = e
    raise err.with_traceback(None) from None


__all__ = ["Function", "Kernel", "Overload", "func", "kernel", "overload"]
