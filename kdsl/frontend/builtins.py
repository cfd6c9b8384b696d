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
from kdsl.ir import CATALOG, Value
from kdsl.ir.ops_math import BINARY_MATH, PREDICATES, UNARY_MATH
from kdsl.ir.types import BOOL, F32, ArrayType, MatrixType, ScalarType, VectorType

Lower = Callable[[Any, list[Any], ast.Call], Any]


class Builtin:
    """A kernel builtin: ``lower(emitter, args, node)`` emits its ops."""

    def __init__(self, name: str, lower: Lower, doc: str, arity: tuple[int, int], group: str,
                 keywords: tuple[str, ...] = ()):  # fmt: skip
        self.name = name
        self.lower = lower
        self.__doc__ = doc
        self.arity = arity
        self.group = group
        #: Keyword arguments the builtin accepts (passed to ``lower`` as keywords).
        self.keywords = keywords

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        raise KdslError(
            f"kdsl.{self.name}() is a kernel builtin: call it inside a @kdsl.kernel or "
            "@kdsl.func, not from Python"
        )

    def __repr__(self) -> str:
        return f"<kdsl builtin {self.name}>"


BUILTINS: dict[str, Builtin] = {}


def _define(name: str, arity: tuple[int, int], doc: str, group: str,
            keywords: tuple[str, ...] = ()):  # fmt: skip
    def deco(fn: Lower) -> Lower:
        if name in BUILTINS:
            raise ValueError(f"builtin {name!r} is defined twice")
        BUILTINS[name] = Builtin(name, fn, doc, arity, group, keywords)
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
def _predicate(name: str) -> Lower:
    # On a vector or matrix (as in Warp): isnan/isinf hold if any component does,
    # isfinite if every component does.
    def lower(em, args, node):
        x = _float_default(em, args[0], node)
        if not isinstance(x.type, VectorType | MatrixType):
            return em.emit(f"math.{name}", x, node=node)
        from kdsl.frontend.builtins_math import components

        combine = "arith.and" if name == "isfinite" else "arith.or"
        out = None
        for c in components(em, x, node):
            r = em.emit(f"math.{name}", c, node=node)
            out = r if out is None else em.emit(combine, out, r, node=node)
        return out

    return lower


for _name, (_fn, _doc) in PREDICATES.items():
    _define(_name, (1, 1), _doc + " On a vector or matrix: "
            + ("every component." if _name == "isfinite" else "any component."),
            "math")(_predicate(_name))  # fmt: skip


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
        if len(args) == 1:  # min(v): the smallest component of a vector (NaN skipped)
            v = em.value(args[0], node)
            if not isinstance(v.type, VectorType):
                raise em.error(KdslTypeError, f"{op[6:]}() of one argument needs a vector, "
                               f"not {v.type}", node)  # fmt: skip
            from kdsl.frontend.builtins_math import components

            args = components(em, v, node)
        vals = _unified(em, args, node)
        out = vals[0]
        for v in vals[1:]:
            out = em.emit(op, out, v, node=node)
        return out

    return lower


_define("min", (1, 8), "The smallest argument (elementwise for vectors); ``min(v)``: the "
        "smallest component.", "math")(
    _minmax("arith.min"))  # fmt: skip
_define("max", (1, 8), "The largest argument (elementwise for vectors); ``max(v)``: the "
        "largest component.", "math")(
    _minmax("arith.max"))  # fmt: skip


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


_ATOMIC_DOCS = {
    "add": "``arr[i...] += value``", "sub": "``arr[i...] -= value``",
    "min": "``arr[i...] = min(arr[i...], value)``", "max": "``arr[i...] = max(arr[i...], value)``",
    "and": "``arr[i...] &= value`` (integers)", "or": "``arr[i...] |= value`` (integers)",
    "xor": "``arr[i...] ^= value`` (integers)", "exch": "``arr[i...] = value``",
}  # fmt: skip
for _kind, _what in _ATOMIC_DOCS.items():
    _define(f"atomic_{_kind}", (3, 6),
            f"``atomic_{_kind}(arr, i..., value)``: atomically {_what}; gives the old value "
            "(componentwise for vectors and matrices).", "memory")(_atomic(_kind))  # fmt: skip


@_define("atomic_cas", (4, 7), "``atomic_cas(arr, i..., compare, value)``: atomically store "
         "``value`` where ``arr[i...]`` equals ``compare`` (bitwise); gives the old value.",
         "memory")  # fmt: skip
def _atomic_cas(em, args, node):
    arr = _array_arg(em, args[0], node, "atomic_cas")
    compare = em.value(args[-2], node, want=arr.type.dtype)
    value = em.value(args[-1], node, want=arr.type.dtype)
    idx = _indices(em, args[1:-2], node)
    return em.emit("kd.atomic_cas", compare, value, arr, *idx, node=node)


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
# Python's ``math.sin`` is the catalog's ``math.sin``: every op of the ``math`` dialect
# that Python's ``math`` module also has (``math.round`` and ``math.sign`` it has not).
for _opdef in CATALOG:
    _dialect, _, _name = _opdef.name.partition(".")
    if _dialect == "math" and hasattr(math, _name):
        PYTHON_ALIASES[getattr(math, _name)] = BUILTINS[_name]
PYTHON_ALIASES[math.pow] = BUILTINS["pow"]
PYTHON_ALIASES[math.fabs] = BUILTINS["abs"]

#: Python types usable as casts: float -> f32, int -> i32, bool -> bool.
PYTHON_CASTS: dict[Any, ScalarType] = {py.float: F32, py.int: ScalarType("int", 32), py.bool: BOOL}


def is_matrix(v: Any) -> bool:
    return isinstance(v, Value) and isinstance(v.type, MatrixType)


def _register_more() -> None:
    # The composed builtins live in their own modules; importing them defines them.
    from kdsl import types as public
    from kdsl.frontend import builtins_linalg, builtins_math  # noqa: F401

    # wp.vector / wp.matrix are type factories in Python scope, constructors in kernels.
    PYTHON_ALIASES[public.vector] = BUILTINS["vector"]
    PYTHON_ALIASES[public.matrix] = BUILTINS["matrix"]


_register_more()

# Quaternion/transform builtins, and normalize() of quaternions (kdsl/frontend/geometry.py).
from kdsl.frontend import geometry as _geometry  # noqa: E402, F401

# print() and printf() (format checking; kdsl/frontend/printing.py).
from kdsl.frontend import printing as _printing  # noqa: E402, F401
