"""The base of the function compiler: locations, errors, constants and typed ops.

``Emitter`` owns the builder, the SSA scope (``vars``: name -> ``Value``) and the
names that may be unassigned (``maybe``). The expression and statement visitors
(``expressions.py``, ``statements.py``) build on these helpers.
"""

from __future__ import annotations

import ast
from typing import Any

import numpy as np

from kdsl.errors import KdslError, KdslNameError, KdslSyntaxError, KdslTypeError
from kdsl.frontend import bfloat16
from kdsl.frontend.source import ParsedSource
from kdsl.frontend.values import default_type, describe, is_weak, literal_fits
from kdsl.ir import Builder, Loc, Value
from kdsl.ir.types import (
    BF16,
    BOOL,
    MatrixType,
    ScalarType,
    Type,
    VectorType,
    elem_type,
    value_shape,
)

_ATOMICS = ("kd.atomic_rmw", "kd.atomic_cas")


class Emitter(ast.NodeVisitor):
    """Shared state and helpers of one function's lowering."""

    def __init__(self, src: ParsedSource) -> None:
        self.src = src
        self.b = Builder()
        self.vars: dict[str, Value] = {}
        self.maybe: set[str] = set()
        self._node: ast.AST | None = None

    # --- locations and errors -------------------------------------------------

    def loc(self, node: ast.AST | None = None) -> Loc:
        return self.src.loc(node if node is not None else self._node)

    def error(self, cls: type[KdslError], msg: str, node: ast.AST | None = None) -> KdslError:
        return cls(msg, self.loc(node), self.src.name)

    def visit(self, node: ast.AST) -> Any:
        saved, saved_loc = self._node, self.b.loc
        if hasattr(node, "lineno"):
            self._node = node
            self.b.loc = self.loc(node)
        try:
            return super().visit(node)
        finally:
            self._node, self.b.loc = saved, saved_loc

    def generic_visit(self, node: ast.AST) -> Any:
        raise self.error(KdslSyntaxError, f"unsupported syntax in a kernel: {_describe_node(node)}")

    # --- ops --------------------------------------------------------------------

    def emit(self, name: str, *operands: Value, node: ast.AST | None = None, **attrs: Any) -> Value:
        """A one-result op typed by its catalog rule; rule errors become located errors."""
        if (
            name in _ATOMICS
            and getattr(operands[1 + (name == "kd.atomic_cas")].type, "dtype", None) is BF16
        ):
            raise self.error(KdslTypeError, "atomic operations on bfloat16 arrays are not "
                             "supported (no backend has 16-bit float atomics); accumulate in "
                             "a float32 array", node)  # fmt: skip
        try:
            v = self.b.value(name, *operands, loc=self.loc(node), **attrs)
        except TypeError as e:
            raise self.error(KdslTypeError, str(e), node) from None
        if v.type is BF16 and name == "kd.load":  # a storage type: kernels see float32
            return bfloat16.load_value(self, v, node)
        return v

    def emit_typed(self, name: str, operands: list[Value], t: Type, node=None, **attrs) -> Value:
        """A one-result op with an explicit result type (casts, constructors)."""
        return self.b.create(name, operands, [t], attrs or None, loc=self.loc(node)).result

    def const(self, x: Any, t: Type, node: ast.AST | None = None) -> Value:
        """A constant of type ``t`` from a Python number (a weak literal)."""
        if isinstance(t, VectorType | MatrixType):
            s = self.const(x, t.elem, node)
            return self.emit_typed("vec.splat", [s], t, node)
        if not isinstance(t, ScalarType):
            raise self.error(KdslTypeError, f"cannot make a constant of type {t}", node)
        why = literal_fits(x, t) if is_weak(x) else None
        if why:
            raise self.error(KdslTypeError, why, node)
        return self.b.constant(x, t, loc=self.loc(node))

    def zero(self, t: Type, node: ast.AST | None = None) -> Value:
        return self.const(False if t == BOOL else 0, t, node)

    def python_value(self, x: Any, node: ast.AST | None = None) -> Any:
        """A captured Python value as a frontend value (weak literal, constant, vector)."""
        if is_weak(x):
            return x
        misuse = getattr(type(x), "__kdsl_misuse__", None)
        if isinstance(misuse, str):  # an object only some constructs accept (wp.adjoint)
            raise self.error(KdslSyntaxError, misuse, node)
        if isinstance(x, np.generic) and x.dtype.kind in "biuf":
            from kdsl.ir.types import scalar_from_numpy

            return self.b.constant(x.item(), scalar_from_numpy(x.dtype), loc=self.loc(node))
        t = getattr(type(x), "__kdsl_type__", None)
        if isinstance(x, np.ndarray) and isinstance(t, VectorType | MatrixType):
            flat = np.ravel(np.asarray(x))
            parts = [self.b.constant(v.item(), t.elem, loc=self.loc(node)) for v in flat]
            return self.emit_typed("vec.construct", parts, t, node)
        return x

    def value(self, x: Any, node: ast.AST | None = None, want: Type | None = None) -> Value:
        """``x`` as an IR value; a weak literal takes ``want`` (or its default type)."""
        if want is BF16:  # storing into a bfloat16 array: round
            return bfloat16.store_value(self, x, node)
        if isinstance(x, Value):
            return x
        if is_weak(x):
            t = want if isinstance(want, ScalarType) else default_type(x)
            if isinstance(want, VectorType | MatrixType):
                t = want.elem
            return self.const(x, t, node)
        raise self.error(KdslTypeError, f"expected a value here, got {describe(x)}", node)

    def coerce_pair(self, a: Any, b: Any, node: ast.AST) -> tuple[Value, Value]:
        """Two operands typed together: a weak literal takes the other side's element type."""
        if is_weak(a) and is_weak(b):
            t = default_type(a)
            tb = default_type(b)
            if t != tb:
                t = tb if tb.is_float else t
            return self.const(a, t, node), self.const(b, t, node)
        if is_weak(a):
            b = self.value(b, node)
            return self.const(a, _elem_or_self(b.type, node, self), node), b
        if is_weak(b):
            a = self.value(a, node)
            return a, self.const(b, _elem_or_self(a.type, node, self), node)
        return self.value(a, node), self.value(b, node)

    def to_bool(self, x: Any, node: ast.AST) -> Value:
        """A condition: bool as is, numbers compared with zero, anything else rejected."""
        if is_weak(x):
            return self.const(bool(x), BOOL, node)
        v = self.value(x, node)
        if v.type == BOOL:
            return v
        if isinstance(v.type, ScalarType):
            return self.emit("arith.cmp", v, self.zero(v.type, node), node=node, pred="ne")
        raise self.error(
            KdslTypeError, f"a condition must be a bool or a number, not {v.type}", node
        )

    def lookup_local(self, name: str, node: ast.AST) -> Value | None:
        if name in self.vars:
            return self.vars[name]
        if name in self.maybe:
            raise self.error(
                KdslNameError,
                f"variable '{name}' may be unassigned here: it is not assigned on every "
                "path that reaches this use",
                node,
            )
        return None


def _elem_or_self(t: Type, node: ast.AST, em: Emitter) -> ScalarType:
    try:
        return elem_type(t)
    except TypeError:
        raise em.error(KdslTypeError, f"cannot combine a literal with a {t}", node) from None


def component_count(t: Type) -> int:
    return int(np.prod(value_shape(t))) if not isinstance(t, ScalarType) else 1


_NODE_NAMES = {
    "ListComp": "list comprehension", "DictComp": "dict comprehension",
    "SetComp": "set comprehension", "GeneratorExp": "generator expression",
    "Lambda": "lambda", "Try": "try/except", "TryStar": "try/except*", "With": "with",
    "AsyncWith": "async with", "AsyncFor": "async for", "AsyncFunctionDef": "async def",
    "Await": "await", "Yield": "yield", "YieldFrom": "yield from", "Global": "global",
    "Nonlocal": "nonlocal", "ClassDef": "class definition", "FunctionDef": "nested def",
    "Delete": "del", "Import": "import", "ImportFrom": "import", "NamedExpr": "walrus (:=)",
    "List": "list", "Dict": "dict", "Set": "set", "JoinedStr": "f-string", "Raise": "raise",
    "Match": "match", "Starred": "starred expression", "Slice": "slice",
}  # fmt: skip


def _describe_node(node: ast.AST) -> str:
    name = type(node).__name__
    return _NODE_NAMES.get(name, name)
