"""A kernel's source fingerprint: what its IR is built from, known without building it.

The kernel cache's source index (``kdsl.compiler.source_index``) keys a kernel on
this digest instead of its optimized IR, so a warm process finds the compiled code
without running the frontend or the passes. The fingerprint covers everything the
frontend reads while it builds a kernel:

- the kernel's source text, file and first line (locations are part of the IR);
- its parameter types (``arg_types``, as IR types: a generic instance's too);
- every name its source reads that is not a parameter, resolved as the frontend
  resolves it (closure cell, then module global, then Python builtin), with each
  ``a.b.c`` attribute chain followed to the value it names, and that value digested:
  numbers and strings by type and ``repr``, NumPy values by dtype, shape and bytes,
  tuples and lists element by element, kdsl types by their IR type (a struct's
  fields, names and alignment), builtins by name, modules by name, and
  ``@kdsl.func`` functions by the same fingerprint, transitively (every overload,
  its custom gradient and replay functions);
- nothing else: the caller adds the options, backend, target and kdsl's own code.

A value it cannot digest (an arbitrary object, a plain Python function outside kdsl,
a global shadowed by a local of the same name whose value it cannot digest) makes the
whole fingerprint ``None`` (an object only used as the base of an attribute, as
``settings`` in ``settings.n``, is named by its type: the value read is ``settings.n``): the kernel is then keyed by its IR as before (correct,
only slower). Names the kernel binds only as parameters are never looked up: the
frontend finds the parameter first.
"""

from __future__ import annotations

import ast
import builtins as pybuiltins
import hashlib
import types
from typing import Any

import numpy as np

from kdsl.ir.types import Type

#: Arrays larger than this (bytes) are not digested: the kernel is keyed by its IR.
_MAX_ARRAY_BYTES = 1 << 20
#: Tuples and lists longer than this are not digested.
_MAX_ITEMS = 4096


class _Opaque(Exception):
    """A value the fingerprint cannot digest (the kernel falls back to its IR key)."""


def source_fingerprint(target: Any) -> str | None:
    """The digest (64 hex digits) of ``target``'s sources and what they read, or None.

    ``target`` is a kernel (or a generic kernel's instance); see the module docstring.
    """
    try:
        return _Walk().target(target, "kernel")
    except Exception:
        # _Opaque, or anything a user's object raises when looked at (a repr, an
        # attribute), or source the frontend cannot read either: it reports that itself.
        return None


class _Walk:
    """One fingerprint computation: memoizes functions (and cuts recursion cycles)."""

    def __init__(self) -> None:
        self.done: dict[int, str] = {}

    def target(self, t: Any, kind: str) -> str:
        """The digest of one compile target (a kernel or a ``@func`` overload)."""
        from kdsl.frontend.kernel import CompileTarget

        src = t.src  # parsed once per target and kept (the frontend reuses it)
        h = hashlib.sha256()
        lines = [kind, src.file, str(src.line_offset), src.text]
        h.update("\0".join(lines).encode())
        try:
            arg_types = CompileTarget.arg_types(t)
        except Exception:
            raise _Opaque from None  # the frontend reports it: let it
        h.update(repr(arg_types).encode())
        params = {a.arg for a in src.tree.args.args}
        scope = _Scope(src.fn)
        for chain in sorted(_chains(src.tree)):
            if chain[0] in params:
                continue
            digest = self.chain(scope, chain)
            if " at 0x" in digest:  # a default repr: an address, never the same twice
                raise _Opaque
            h.update(b"\0" + ".".join(chain).encode() + b"=" + digest.encode())
        return h.hexdigest()

    def chain(self, scope: _Scope, chain: tuple[str, ...]) -> str:
        """The digest of what ``a.b.c`` names (as far as it resolves).

        The frontend reads only the value at the end of a chain (``a`` and ``a.b`` are
        bases it takes an attribute of), so an object in the middle that cannot be
        digested (``settings`` in ``settings.n``) is named by its type; the end value
        must be digested. A bare ``settings`` elsewhere is a chain of its own.
        """
        found, value = scope.lookup(chain[0])
        if not found:
            return "<undefined>"  # a local, or a name the frontend reports
        values, missing = [value], ""
        for attr in chain[1:]:
            try:
                value = getattr(value, attr)
            except Exception:
                missing = f"|<no .{attr}>"
                break
            values.append(value)
        parts = [self.base(v) for v in values[:-1]] + [self.value(values[-1])]
        return "|".join(parts) + missing

    def base(self, v: Any) -> str:
        """The digest of an object the frontend takes an attribute of."""
        try:
            return self.value(v)
        except _Opaque:
            return f"base:{_qual(v if isinstance(v, type) else type(v))}"

    def value(self, v: Any) -> str:
        """The digest of one value the frontend may read (raises ``_Opaque``)."""
        if v is None or isinstance(v, bool | int | float | complex | str | bytes):
            return f"{type(v).__module__}.{type(v).__qualname__}:{v!r}"
        if isinstance(v, np.generic):
            return f"np:{v.dtype.str}:{v.tobytes().hex()}"
        if isinstance(v, np.ndarray):
            if v.nbytes > _MAX_ARRAY_BYTES or v.dtype.hasobject:
                raise _Opaque
            data = hashlib.sha256(np.ascontiguousarray(v).tobytes()).hexdigest()
            return f"ndarray:{_qual(type(v))}:{v.dtype.str}:{v.shape}:{data}"
        if isinstance(v, tuple | list):
            if len(v) > _MAX_ITEMS:
                raise _Opaque
            return f"{type(v).__name__}({','.join(self.value(x) for x in v)})"
        if isinstance(v, types.ModuleType):
            return f"module:{v.__name__}"
        if isinstance(v, type):
            return self.type_(v)
        return self.object(v)

    def type_(self, v: type) -> str:
        ir = getattr(v, "__kdsl_type__", None)
        if isinstance(ir, Type):  # (``kdsl.array`` has a property of that name instead)
            keywords = getattr(v, "__kdsl_keywords__", ())
            return f"type:{_qual(v)}:{ir!r}:{keywords!r}"
        if v.__module__ in ("builtins", "typing", "numpy") or _in_kdsl(v.__module__):
            return f"class:{_qual(v)}"
        raise _Opaque  # a user's class: what the frontend takes from it is unknown

    def object(self, v: Any) -> str:
        from kdsl.frontend.builtins_base import Builtin
        from kdsl.frontend.grad import GradOf

        if isinstance(v, Builtin):
            return f"builtin:{v.name}"
        overloads = getattr(v, "__kdsl_overloads__", None)
        if overloads is not None:
            return self.function(v, overloads)
        if getattr(v, "__kdsl_kernel__", False):
            return self.memo(v, lambda: f"kernel:{self.target(v, 'kernel')}")
        if isinstance(v, GradOf):
            return f"grad:{self.value(v.fn)}"
        if isinstance(v, types.BuiltinFunctionType):
            return f"cfunction:{v.__module__}.{v.__qualname__}"
        if isinstance(v, types.FunctionType) and _in_kdsl(v.__module__):
            return f"kdsl-function:{_qual(v)}"
        if v is getattr(pybuiltins, getattr(v, "__name__", ""), None):
            return f"pybuiltin:{v.__name__}"
        if isinstance(getattr(type(v), "__kdsl_misuse__", None), str):
            return f"marker:{_qual(type(v))}"  # e.g. kdsl.adjoint, a stateless singleton
        if type(v).__module__ == "typing":
            return f"typing:{v!r}"
        raise _Opaque

    def function(self, f: Any, overloads: list[Any]) -> str:
        def digest() -> str:
            parts = [f"func:{getattr(f, 'name', '?')}"]
            for ov in overloads:
                parts.append(self.target(ov, "func"))
                for extra in ("custom_grad", "custom_replay"):
                    g = getattr(ov, extra, None)
                    if g is not None:
                        parts.append(f"{extra}:{self.target(g, extra)}")
            return hashlib.sha256("\0".join(parts).encode()).hexdigest()

        return self.memo(f, digest)

    def memo(self, obj: Any, make: Any) -> str:
        key = id(obj)
        hit = self.done.get(key)
        if hit is None:
            # A recursive call sees its place in the walk (deterministic: chains are sorted).
            self.done[key] = f"<recursive {len(self.done)}>"
            hit = self.done[key] = make()
        return hit


class _Scope:
    """Name lookup as the frontend does it: closure cell, module global, Python builtin."""

    def __init__(self, fn: Any) -> None:
        self.closure: dict[str, Any] = {}
        for name, cell in zip(fn.__code__.co_freevars, fn.__closure__ or ()):
            try:
                self.closure[name] = cell.cell_contents
            except ValueError:  # an empty cell
                continue
        self.globals = fn.__globals__

    def lookup(self, name: str) -> tuple[bool, Any]:
        if name in self.closure:
            return True, self.closure[name]
        if name in self.globals:
            return True, self.globals[name]
        if hasattr(pybuiltins, name):
            return True, getattr(pybuiltins, name)
        return False, None


def _chains(tree: ast.AST) -> set[tuple[str, ...]]:
    """Every ``name`` and ``name.attr.attr`` the function's source reads (longest chains)."""
    out: set[tuple[str, ...]] = set()
    inner: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and id(node) not in inner:
            chain: list[str] = []
            cur: ast.AST = node
            while isinstance(cur, ast.Attribute):
                chain.append(cur.attr)
                inner.add(id(cur.value))
                cur = cur.value
            if isinstance(cur, ast.Name):
                out.add((cur.id, *reversed(chain)))
        elif isinstance(node, ast.Name) and id(node) not in inner:
            out.add((node.id,))
    return out


def _qual(x: Any) -> str:
    return f"{getattr(x, '__module__', '?')}.{getattr(x, '__qualname__', '?')}"


def _in_kdsl(module: str | None) -> bool:
    return bool(module) and (module == "kdsl" or module.startswith("kdsl."))  # type: ignore[union-attr]
