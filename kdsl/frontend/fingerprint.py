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

The source itself is read through ``SourceFacts``: what the walk takes from a
function's source (its file, first line, a digest of its text, its parameter names and
the chains it reads). Parsing costs 1 to 2 ms a function (``inspect`` tokenizes the
file to find the function's end, then ``ast.parse``), so the caller may pass a
``SourceMemo`` (kept in the kernel cache by ``kdsl.compiler.source_index``): facts
recorded by an earlier process, keyed by the function's code (file, first line,
qualified name) and used while the file's bytes are those they were recorded from (a
sha256 of the file, tens of microseconds). Facts are recorded only from a parse made by
this walk while the file read the same before and after it, and whose text is the
file's at that line (``linecache`` can serve an older copy of a file).
"""

from __future__ import annotations

import ast
import builtins as pybuiltins
import hashlib
import importlib.util
import inspect
import io
import types
from dataclasses import dataclass
from typing import Any

import numpy as np

from kdsl.ir.types import Type

#: Arrays larger than this (bytes) are not digested: the kernel is keyed by its IR.
_MAX_ARRAY_BYTES = 1 << 20
#: Tuples and lists longer than this are not digested.
_MAX_ITEMS = 4096


@dataclass(frozen=True)
class SourceFacts:
    """What the fingerprint reads of one function's source (see the module docstring)."""

    file: str
    #: sha256 of the file's bytes when the facts were recorded ("" when not recordable).
    file_digest: str
    line_offset: int
    text_digest: str
    params: tuple[str, ...]
    chains: tuple[tuple[str, ...], ...]

    def as_json(self) -> list:
        """The facts as JSON-able data (``SourceMemo.as_json``)."""
        return [self.file, self.file_digest, self.line_offset, self.text_digest,
                list(self.params), [list(c) for c in self.chains]]  # fmt: skip

    @classmethod
    def from_json(cls, data: list) -> SourceFacts:
        """Facts from ``as_json`` data (raises on malformed data)."""
        file, file_digest, line_offset, text_digest, params, chains = data
        return cls(str(file), str(file_digest), int(line_offset), str(text_digest),
                   tuple(map(str, params)), tuple(tuple(map(str, c)) for c in chains))  # fmt: skip


class SourceMemo:
    """Recorded ``SourceFacts`` by function (its code's file, first line and qualified
    name); ``changed`` says a walk recorded new facts (the caller then stores it)."""

    def __init__(self, facts: dict[tuple[str, int, str], SourceFacts] | None = None) -> None:
        self.facts = dict(facts or {})
        self.changed = False
        self._digests: dict[str, str | None] = {}  # file -> sha256 now, once per memo
        self._used: set[tuple[str, int, str]] = set()

    def get(self, fn: Any) -> SourceFacts | None:
        """The facts of ``fn`` when recorded and its file's bytes are unchanged since."""
        where = _where(fn)
        got = self.facts.get(where)
        if got is None:
            return None
        if got.file not in self._digests:
            data = _read(got.file)
            self._digests[got.file] = None if data is None else hashlib.sha256(data).hexdigest()
        if self._digests[got.file] != got.file_digest:
            return None
        self._used.add(where)
        return got

    def record(self, fn: Any, facts: SourceFacts) -> None:
        """Remember the facts of ``fn``."""
        where = _where(fn)
        self._used.add(where)
        if self.facts.get(where) != facts:
            self.facts[where] = facts
            self.changed = True

    def as_json(self) -> list:
        """The facts recorded or used since this memo was made (all of them when none
        were: stale facts of functions that moved are not kept), as JSON-able data."""
        keep = self._used or self.facts.keys()
        return [[list(w), self.facts[w].as_json()] for w in sorted(keep) if w in self.facts]

    @classmethod
    def from_json(cls, data: list) -> SourceMemo:
        """The memo ``as_json`` gave (raises on malformed data)."""
        out: dict[tuple[str, int, str], SourceFacts] = {}
        for (file, line, qualname), facts in data:
            out[(str(file), int(line), str(qualname))] = SourceFacts.from_json(facts)
        return cls(out)


def _where(fn: Any) -> tuple[str, int, str]:
    code = fn.__code__
    return (code.co_filename, code.co_firstlineno, getattr(fn, "__qualname__", code.co_name))


def _read(path: str) -> bytes | None:
    try:
        with open(path, "rb") as f:
            return f.read()
    except OSError:
        return None


def source_facts(t: Any, memo: SourceMemo | None) -> SourceFacts:
    """The ``SourceFacts`` of compile target ``t``: from ``memo`` while its file is
    unchanged, else from its parsed source (recorded in ``memo`` when that is safe: see
    the module docstring). Raises what parsing raises."""
    if memo is not None:
        got = memo.get(t.fn)
        if got is not None:
            return got
    fresh = "src" not in t.__dict__  # parsed here, not earlier (maybe from an older file)
    path = inspect.getsourcefile(t.fn) or t.fn.__code__.co_filename
    before = _read(path) if fresh and memo is not None else None
    src = t.src  # parsed once per target and kept (the frontend reuses it)
    file_digest = ""
    if before is not None and src.file == path and _read(path) == before:
        lines = io.StringIO(importlib.util.decode_source(before)).readlines()
        if "".join(lines[src.line_offset : src.line_offset + src.text.count("\n")]) == src.text:
            file_digest = hashlib.sha256(before).hexdigest()
    facts = SourceFacts(
        src.file, file_digest, src.line_offset, hashlib.sha256(src.text.encode()).hexdigest(),
        tuple(a.arg for a in src.tree.args.args), tuple(sorted(_chains(src.tree))),
    )  # fmt: skip
    if memo is not None and file_digest:
        memo.record(t.fn, facts)
    return facts


class _Opaque(Exception):
    """A value the fingerprint cannot digest (the kernel falls back to its IR key)."""


def source_fingerprint(target: Any, memo: SourceMemo | None = None) -> str | None:
    """The digest (64 hex digits) of ``target``'s sources and what they read, or None.

    ``target`` is a kernel (or a generic kernel's instance); see the module docstring.
    ``memo`` gives recorded source facts and receives new ones.
    """
    try:
        return _Walk(memo).target(target, "kernel")
    except Exception:
        # _Opaque, or anything a user's object raises when looked at (a repr, an
        # attribute), or source the frontend cannot read either: it reports that itself.
        return None


class _Walk:
    """One fingerprint computation: memoizes functions (and cuts recursion cycles)."""

    def __init__(self, memo: SourceMemo | None = None) -> None:
        self.done: dict[int, str] = {}
        self.sources = memo

    def target(self, t: Any, kind: str) -> str:
        """The digest of one compile target (a kernel or a ``@func`` overload)."""
        from kdsl.frontend.kernel import CompileTarget

        src = source_facts(t, self.sources)
        h = hashlib.sha256()
        lines = [kind, src.file, str(src.line_offset), src.text_digest]
        h.update("\0".join(lines).encode())
        try:
            arg_types = CompileTarget.arg_types(t)
        except Exception:
            raise _Opaque from None  # the frontend reports it: let it
        h.update(repr(arg_types).encode())
        params = set(src.params)
        scope = _Scope(t.fn)
        for chain in src.chains:
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
