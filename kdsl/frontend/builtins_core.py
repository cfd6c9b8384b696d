"""The builtins that map straight onto catalog ops: math, vector, logic and memory.

``sin``, ``atan2``, ``isnan``, ``min``/``max``, ``dot``, ``normalize``, ``select``,
``atomic_add``, ``load``/``store``, ``len``, ``tid``... Each lowers to one op of the
same name, or a few (``min(v)`` folds a vector's components). ``TABLE`` also maps
Python's ``abs``/``min``/``max``/``len``/``round``/``pow`` and ``math``'s functions onto
these builtins.
"""

from __future__ import annotations

import builtins as py
import math
from typing import Any

from kdsl.errors import KdslTypeError
from kdsl.frontend.builtins_base import BuiltinTable, Lower, float_default, unified
from kdsl.frontend.builtins_math import components
from kdsl.frontend.geometry import normalize_quat
from kdsl.frontend.values import is_weak
from kdsl.ir import CATALOG, Value
from kdsl.ir.ops_math import BINARY_MATH, PREDICATES, UNARY_MATH
from kdsl.ir.types import I32, ArrayType, MatrixType, VectorType

TABLE = BuiltinTable(__name__)


def _unary(op: str, float_only: bool) -> Lower:
    def lower(em, args, node):
        x = float_default(em, args[0], node) if float_only else em.value(args[0], node)
        return em.emit(op, x, node=node)

    return lower


for _name, (_fn, _float_only, _doc) in UNARY_MATH.items():
    TABLE.define(_name, (1, 1), _doc, "math")(_unary(f"math.{_name}", _float_only))


def _predicate(name: str) -> Lower:
    # On a vector or matrix (as in Warp): isnan/isinf hold if any component does,
    # isfinite if every component does.
    def lower(em, args, node):
        x = float_default(em, args[0], node)
        if not isinstance(x.type, VectorType | MatrixType):
            return em.emit(f"math.{name}", x, node=node)
        combine = "arith.and" if name == "isfinite" else "arith.or"
        out = None
        for c in components(em, x, node):
            r = em.emit(f"math.{name}", c, node=node)
            out = r if out is None else em.emit(combine, out, r, node=node)
        return out

    return lower


for _name, (_fn, _doc) in PREDICATES.items():
    TABLE.define(_name, (1, 1), _doc + " On a vector or matrix: "
                 + ("every component." if _name == "isfinite" else "any component."),
                 "math")(_predicate(_name))  # fmt: skip


def _binary(op: str, floats: bool = False) -> Lower:
    def lower(em, args, node):
        if floats and all(is_weak(a) for a in args):
            args = [float(a) for a in args]
        a, b = unified(em, args, node)
        return em.emit(op, a, b, node=node)

    return lower


for _name, (_fn, _doc) in BINARY_MATH.items():
    TABLE.define(_name, (2, 2), _doc, "math")(_binary(f"math.{_name}", floats=True))
TABLE.define("pow", (2, 2), "``x`` raised to ``y`` (floats).", "math")(_binary("arith.pow", True))


def _minmax(op: str) -> Lower:
    def lower(em, args, node):
        reduce = len(args) == 1
        if reduce:  # min(v): the smallest component of a vector (NaN skipped)
            v = em.value(args[0], node)
            if not isinstance(v.type, VectorType):
                raise em.error(KdslTypeError, f"{op[6:]}() of one argument needs a vector, "
                               f"not {v.type}", node)  # fmt: skip
            args = components(em, v, node)
        vals = unified(em, args, node)
        out = vals[0]
        for v in vals[1:]:  # op(new, so far): ties keep the earlier value and its gradient
            out = em.emit(op, v, out, node=node) if reduce else em.emit(op, out, v, node=node)
        return out

    return lower


TABLE.define("min", (1, 8), "The smallest argument (elementwise for vectors); ``min(v)``: the "
             "smallest component.", "math")(
    _minmax("arith.min"))  # fmt: skip
TABLE.define("max", (1, 8), "The largest argument (elementwise for vectors); ``max(v)``: the "
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
    ("transpose", 1, "Matrix transpose."),
    ("outer", 2, "Outer product of two vectors: a matrix."),
]:
    TABLE.define(_name, (_n, _n), _doc, "vector")(_vec_op(f"vec.{_name}", _n))


@TABLE.define("normalize", (1, 1), "The vector scaled to unit length (zero stays zero).", "vector")
def _normalize(em, args, node):
    q = normalize_quat(em, args[0], node)
    return q if q is not None else em.emit("vec.normalize", em.value(args[0], node), node=node)


@TABLE.define("mul", (2, 2), "Product; matrix times vector/matrix is the matrix product.", "vector")
def _mul(em, args, node):
    return em.binop("mul", args[0], args[1], node)


@TABLE.define("select", (3, 3), "Warp's order: ``select(cond, value_if_false, value_if_true)``.",
              "logic")  # fmt: skip
def _select(em, args, node):
    c = em.to_bool(args[0], node)
    f, t = unified(em, args[1:], node)
    return em.emit("arith.select", c, t, f, node=node)


@TABLE.define("where", (3, 3), "``where(cond, a, b)``: ``a`` if ``cond`` else ``b``.", "logic")
def _where(em, args, node):
    c = em.to_bool(args[0], node)
    a, b = unified(em, args[1:], node)
    return em.emit("arith.select", c, a, b, node=node)


def _array_arg(em, x: Any, node, what: str) -> Value:
    v = em.value(x, node)
    if not isinstance(v.type, ArrayType):
        raise em.error(KdslTypeError, f"{what}() needs an array first, not {v.type}", node)
    return v


def _indices(em, xs: list[Any], node) -> list[Value]:
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
    TABLE.define(f"atomic_{_kind}", (3, 6),
                 f"``atomic_{_kind}(arr, i..., value)``: atomically {_what}; gives the old value "
                 "(componentwise for vectors and matrices).", "memory")(_atomic(_kind))  # fmt: skip


@TABLE.define("atomic_cas", (4, 7), "``atomic_cas(arr, i..., compare, value)``: atomically store "
              "``value`` where ``arr[i...]`` equals ``compare`` (bitwise); gives the old value.",
              "memory")  # fmt: skip
def _atomic_cas(em, args, node):
    arr = _array_arg(em, args[0], node, "atomic_cas")
    compare = em.value(args[-2], node, want=arr.type.dtype)
    value = em.value(args[-1], node, want=arr.type.dtype)
    idx = _indices(em, args[1:-2], node)
    return em.emit("kd.atomic_cas", compare, value, arr, *idx, node=node)


@TABLE.define(
    "load", (2, 5), "``load(arr, i...)``: ``arr[i...]`` (Warp's older spelling).", "memory"
)
def _load(em, args, node):
    arr = _array_arg(em, args[0], node, "load")
    return em.emit("kd.load", arr, *_indices(em, args[1:], node), node=node)


@TABLE.define("store", (3, 6), "``store(arr, i..., value)``: ``arr[i...] = value``.", "memory")
def _store(em, args, node):
    arr = _array_arg(em, args[0], node, "store")
    value = em.value(args[-1], node, want=arr.type.dtype)
    em.b.create("kd.store", [value, arr, *_indices(em, args[1:-1], node)], [], loc=em.loc(node))
    return None


@TABLE.define("len", (1, 1), "Length of an array's first dimension, or a vector's size.", "memory")
def _len(em, args, node):
    v = em.value(args[0], node)
    if isinstance(v.type, ArrayType):
        return em.emit("kd.array_shape", v, node=node, dim=0)
    length = getattr(v.type, "length", None) or getattr(v.type, "rows", None)
    if length is None:
        raise em.error(KdslTypeError, f"len() needs an array, vector or matrix, not {v.type}", node)
    return int(length)


@TABLE.define("tid", (0, 0), "The thread index: ``i = tid()``, ``i, j = tid()`` (1 to 4 dims).",
              "memory")  # fmt: skip
def _tid(em, args, node):
    return em.tid(1, node)


# Python's own functions that mean these builtins in kernels.
for _python, _name in [(py.abs, "abs"), (py.min, "min"), (py.max, "max"), (py.len, "len"),
                       (py.round, "round"), (py.pow, "pow"), (math.pow, "pow"),
                       (math.fabs, "abs")]:  # fmt: skip
    TABLE.alias(_python, _name)
# Python's ``math.sin`` is the catalog's ``math.sin``: every op of the ``math`` dialect
# that Python's ``math`` module also has (``math.round`` and ``math.sign`` it has not).
for _opdef in CATALOG:
    _dialect, _, _name = _opdef.name.partition(".")
    if _dialect == "math" and hasattr(math, _name):
        TABLE.alias(getattr(math, _name), _name)
