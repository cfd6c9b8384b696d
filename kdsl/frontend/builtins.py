"""The kernel-language builtins: ``wp.sin``, ``wp.dot``, ``wp.atomic_add``...

Each ``Builtin`` maps a call in kernel code to IR ops of the catalog (this table
adds no op of its own). ``BUILTINS`` lists them by name; ``api.py`` exports each as
an attribute of ``kdsl``. Python's ``abs``/``min``/``max``/``len`` and ``math``'s
functions map onto the same entries (``PYTHON_ALIASES``).
"""

from __future__ import annotations

import ast
import builtins as py
import math
from collections.abc import Callable
from typing import Any

from kdsl.errors import KdslError, KdslTypeError
from kdsl.frontend.values import is_weak
from kdsl.ir import Value
from kdsl.ir.ops_math import BINARY_MATH, PREDICATES, UNARY_MATH
from kdsl.ir.types import BOOL, F32, ArrayType, MatrixType, ScalarType

Lower = Callable[[Any, list[Any], ast.Call], Any]


class Builtin:
    """A kernel builtin: ``lower(emitter, args, node)`` emits its ops."""

    def __init__(self, name: str, lower: Lower, doc: str, arity: tuple[int, int], group: str):
        self.name = name
        self.lower = lower
        self.__doc__ = doc
        self.arity = arity
        self.group = group

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        raise KdslError(
            f"kdsl.{self.name}() is a kernel builtin: call it inside a @kdsl.kernel or "
            "@kdsl.func, not from Python"
        )

    def __repr__(self) -> str:
        return f"<kdsl builtin {self.name}>"


BUILTINS: dict[str, Builtin] = {}


def _define(name: str, arity: tuple[int, int], doc: str, group: str):
    def deco(fn: Lower) -> Lower:
        BUILTINS[name] = Builtin(name, fn, doc, arity, group)
        return fn

    return deco


def _unified(em, args: list[Any], node: ast.AST) -> list[Value]:
    """Arguments typed together: weak literals take the first typed argument's type."""
    typed = next((a for a in args if isinstance(a, Value)), None)
    if typed is None:
        floats = any(isinstance(a, float) for a in args)
        return [em.value(float(a) if floats and not isinstance(a, bool) else a, node)
                for a in args]  # fmt: skip
    return [em.coerce_pair(a, typed, node)[0] if is_weak(a) else em.value(a, node) for a in args]


def _float_default(em, x: Any, node) -> Value:
    # A lone int literal passed to a float function (sqrt(2)) is a float, as in Python.
    if is_weak(x) and not isinstance(x, bool):
        return em.const(float(x), F32, node)
    return em.value(x, node)


def _unary(op: str, float_only: bool) -> Lower:
    def lower(em, args, node):
        x = _float_default(em, args[0], node) if float_only else em.value(args[0], node)
        return em.emit(op, x, node=node)

    return lower


for _name, (_fn, _float_only, _doc) in UNARY_MATH.items():
    _define(_name, (1, 1), _doc, "math")(_unary(f"math.{_name}", _float_only))
for _name, (_fn, _doc) in PREDICATES.items():
    _define(_name, (1, 1), _doc, "math")(_unary(f"math.{_name}", True))


def _binary(op: str, floats: bool = False) -> Lower:
    def lower(em, args, node):
        if floats and all(is_weak(a) for a in args):
            args = [float(a) for a in args]
        a, b = _unified(em, args, node)
        return em.emit(op, a, b, node=node)

    return lower


for _name, (_fn, _doc) in BINARY_MATH.items():
    _define(_name, (2, 2), _doc, "math")(_binary(f"math.{_name}", floats=True))
_define("pow", (2, 2), "``x`` raised to ``y`` (floats).", "math")(_binary("arith.pow", True))


def _minmax(op: str) -> Lower:
    def lower(em, args, node):
        vals = _unified(em, args, node)
        out = vals[0]
        for v in vals[1:]:
            out = em.emit(op, out, v, node=node)
        return out

    return lower


_define("min", (2, 8), "The smallest argument (elementwise for vectors).", "math")(
    _minmax("arith.min"))  # fmt: skip
_define("max", (2, 8), "The largest argument (elementwise for vectors).", "math")(
    _minmax("arith.max"))  # fmt: skip


@_define("clamp", (3, 3), "``x`` limited to ``[lo, hi]``: ``min(max(x, lo), hi)``.", "math")
def _clamp(em, args, node):
    x, lo, hi = _unified(em, args, node)
    return em.emit("arith.min", em.emit("arith.max", x, lo, node=node), hi, node=node)


def _vec_op(op: str, n: int) -> Lower:
    def lower(em, args, node):
        return em.emit(op, *[em.value(a, node) for a in args[:n]], node=node)

    return lower


for _name, _n, _doc in [
    ("dot", 2, "Dot product of two vectors."),
    ("cross", 2, "Cross product of two 3-vectors."),
    ("length", 1, "Euclidean length of a vector."),
    ("length_sq", 1, "Squared length of a vector."),
    ("normalize", 1, "The vector scaled to unit length (zero stays zero)."),
    ("transpose", 1, "Matrix transpose."),
    ("outer", 2, "Outer product of two vectors: a matrix."),
]:
    _define(_name, (_n, _n), _doc, "vector")(_vec_op(f"vec.{_name}", _n))


@_define("mul", (2, 2), "Product; matrix times vector/matrix is the matrix product.", "vector")
def _mul(em, args, node):
    return em.binop("mul", args[0], args[1], node)


@_define("select", (3, 3), "Warp's order: ``select(cond, value_if_false, value_if_true)``.",
         "logic")  # fmt: skip
def _select(em, args, node):
    c = em.to_bool(args[0], node)
    f, t = _unified(em, args[1:], node)
    return em.emit("arith.select", c, t, f, node=node)


@_define("where", (3, 3), "``where(cond, a, b)``: ``a`` if ``cond`` else ``b``.", "logic")
def _where(em, args, node):
    c = em.to_bool(args[0], node)
    a, b = _unified(em, args[1:], node)
    return em.emit("arith.select", c, a, b, node=node)


def _array_arg(em, x: Any, node, what: str) -> Value:
    v = em.value(x, node)
    if not isinstance(v.type, ArrayType):
        raise em.error(KdslTypeError, f"{what}() needs an array first, not {v.type}", node)
    return v


def _indices(em, xs: list[Any], node) -> list[Value]:
    from kdsl.ir.types import I32

    return [em.value(x, node, want=I32) for x in xs]


def _atomic(kind: str) -> Lower:
    def lower(em, args, node):
        arr = _array_arg(em, args[0], node, f"atomic_{kind}")
        value = em.value(args[-1], node, want=arr.type.dtype)
        idx = _indices(em, args[1:-1], node)
        return em.emit("kd.atomic_rmw", value, arr, *idx, node=node, kind=kind)

    return lower


for _kind in ("add", "sub", "min", "max"):
    _define(f"atomic_{_kind}", (3, 6),
            f"``atomic_{_kind}(arr, i..., value)``: atomic {_kind} into ``arr[i...]``; "
            "gives the old value.", "memory")(_atomic(_kind))  # fmt: skip


@_define("load", (2, 5), "``load(arr, i...)``: ``arr[i...]`` (Warp's older spelling).", "memory")
def _load(em, args, node):
    arr = _array_arg(em, args[0], node, "load")
    return em.emit("kd.load", arr, *_indices(em, args[1:], node), node=node)


@_define("store", (3, 6), "``store(arr, i..., value)``: ``arr[i...] = value``.", "memory")
def _store(em, args, node):
    arr = _array_arg(em, args[0], node, "store")
    value = em.value(args[-1], node, want=arr.type.dtype)
    em.b.create("kd.store", [value, arr, *_indices(em, args[1:-1], node)], [], loc=em.loc(node))
    return None


@_define("len", (1, 1), "Length of an array's first dimension, or a vector's size.", "memory")
def _len(em, args, node):
    v = em.value(args[0], node)
    if isinstance(v.type, ArrayType):
        return em.emit("kd.array_shape", v, node=node, dim=0)
    length = getattr(v.type, "length", None) or getattr(v.type, "rows", None)
    if length is None:
        raise em.error(KdslTypeError, f"len() needs an array, vector or matrix, not {v.type}", node)
    return int(length)


@_define("tid", (0, 0), "The thread index: ``i = tid()``, ``i, j = tid()`` (1 to 4 dims).",
         "memory")  # fmt: skip
def _tid(em, args, node):
    return em.tid(1, node)


def cast(em, t: ScalarType, args: list[Any], node: ast.AST) -> Value:
    """``float32(x)``/``float(x)``/``int(x)``: a conversion (or a typed constant)."""
    if not args:
        return em.zero(t, node)
    x = args[0]
    if is_weak(x):
        if t.is_int and isinstance(x, float):
            x = math.trunc(x)
        elif t.is_float:
            x = float(x)
        elif t.is_bool:
            x = py.bool(x)
        return em.const(x, t, node)
    v = em.value(x, node)
    if not isinstance(v.type, ScalarType):
        raise em.error(KdslTypeError, f"cannot convert a {v.type} to the scalar {t}", node)
    if v.type == t:
        return v
    return em.emit_typed("arith.cast", [v], t, node)


#: Python builtins and ``math`` members that mean a kdsl builtin (or a constant).
PYTHON_ALIASES: dict[Any, Any] = {
    py.abs: BUILTINS["abs"], py.min: BUILTINS["min"], py.max: BUILTINS["max"],
    py.len: BUILTINS["len"], py.round: BUILTINS["round"], py.pow: BUILTINS["pow"],
}  # fmt: skip
for _name in ("sqrt", "exp", "log", "log2", "log10", "sin", "cos", "tan", "asin", "acos",
              "atan", "atan2", "sinh", "cosh", "tanh", "floor", "ceil", "trunc", "isnan",
              "isinf", "isfinite", "erf", "erfc", "copysign", "pow", "cbrt", "exp2"):  # fmt: skip
    if hasattr(math, _name):
        PYTHON_ALIASES[getattr(math, _name)] = BUILTINS[_name]
PYTHON_ALIASES[math.fabs] = BUILTINS["abs"]

#: Python types usable as casts: float -> f32, int -> i32, bool -> bool.
PYTHON_CASTS: dict[Any, ScalarType] = {py.float: F32, py.int: ScalarType("int", 32), py.bool: BOOL}


def is_matrix(v: Any) -> bool:
    return isinstance(v, Value) and isinstance(v.type, MatrixType)
