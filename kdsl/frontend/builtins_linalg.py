"""Vector and matrix builtins composed from catalog ops (Warp's "Vector Math" group).

``cw_mul``, ``cw_div``, ``ddot``, ``trace``, ``diag``, ``get_diag``, ``skew``,
``identity``, ``argmin``, ``argmax``, the norms, ``matrix_from_rows``/``cols`` and the
in-kernel ``vector(...)``/``matrix(...)`` constructors lower to ``vec``/``arith`` ops
here; ``determinant`` and ``inverse`` call the ``@kdsl.func`` code of
``kdsl.stdlib.linalg`` (and ``inverse`` of a quaternion or transform calls
``kdsl.stdlib.quat``/``transform``). Sums run left to right, row-major.
"""

from __future__ import annotations

import importlib
from typing import Any

from kdsl import types as public
from kdsl.errors import KdslTypeError
from kdsl.frontend.builtins_base import BuiltinTable
from kdsl.frontend.builtins_math import assemble, components, require_float
from kdsl.frontend.emitter import component_count
from kdsl.frontend.values import describe, is_weak
from kdsl.ir import Value
from kdsl.ir.types import (
    F32,
    I32,
    U32,
    MatrixType,
    QuatType,
    ScalarType,
    TransformType,
    VectorType,
    elem_type,
)

TABLE = BuiltinTable(__name__)


def _vector(em, x: Any, name: str, node, float_only: bool = False) -> Value:
    v = em.value(x, node) if not is_weak(x) else None
    if v is None or not isinstance(v.type, VectorType):
        got = v.type if v is not None else describe(x)
        raise em.error(KdslTypeError, f"{name}() needs a vector, not {got}", node)
    return require_float(em, v, name, node) if float_only else v


def _matrix(em, x: Any, name: str, node, square: bool = False) -> Value:
    v = em.value(x, node) if not is_weak(x) else None
    if v is None or not isinstance(v.type, MatrixType):
        got = v.type if v is not None else describe(x)
        raise em.error(KdslTypeError, f"{name}() needs a matrix, not {got}", node)
    if square and v.type.rows != v.type.cols:
        raise em.error(KdslTypeError, f"{name}() needs a square matrix, not {v.type}", node)
    return v


def _sum(em, parts: list[Value], node) -> Value:
    out = parts[0]
    for p in parts[1:]:
        out = em.emit("arith.add", out, p, node=node)
    return out


def _same_composites(em, args: list[Any], name: str, node) -> tuple[Value, Value]:
    a, b = (em.value(x, node) if not is_weak(x) else x for x in args)
    for v in (a, b):
        if not (isinstance(v, Value) and isinstance(v.type, VectorType | MatrixType)):
            got = v.type if isinstance(v, Value) else describe(v)
            raise em.error(KdslTypeError, f"{name}() needs two vectors or matrices, not {got}",
                           node)  # fmt: skip
    if a.type != b.type:
        raise em.error(KdslTypeError, f"{name}() needs two values of one type, got {a.type} "
                       f"and {b.type}", node)  # fmt: skip
    return a, b


def _componentwise(op: str, name: str):
    def lower(em, args, node):
        a, b = _same_composites(em, args, name, node)
        return em.emit(op, a, b, node=node)

    return lower


TABLE.define("cw_mul", (2, 2), "Componentwise product of two vectors or matrices of one type.",
             "vector")(_componentwise("arith.mul", "cw_mul"))  # fmt: skip
TABLE.define("cw_div", (2, 2), "Componentwise quotient of two vectors or matrices of one type "
             "(integer components follow ``/``: division by zero gives 0).", "vector")(
    _componentwise("arith.div", "cw_div"))  # fmt: skip


@TABLE.define("ddot", (2, 2), "Double dot product of two matrices: the sum of their componentwise "
              "product.", "vector")  # fmt: skip
def _ddot(em, args, node):
    a, b = _same_composites(em, args, "ddot", node)
    if not isinstance(a.type, MatrixType):
        raise em.error(KdslTypeError, f"ddot() needs two matrices, not {a.type}", node)
    return _sum(em, components(em, em.emit("arith.mul", a, b, node=node), node), node)


def _diagonal(em, m: Value, node) -> list[Value]:
    return [em.emit("vec.extract", m, em.const(i, I32, node), em.const(i, I32, node), node=node)
            for i in range(m.type.rows)]  # fmt: skip


@TABLE.define("trace", (1, 1), "Sum of the diagonal of a square matrix.", "vector")
def _trace(em, args, node):
    return _sum(em, _diagonal(em, _matrix(em, args[0], "trace", node, square=True), node), node)


@TABLE.define("get_diag", (1, 1), "The diagonal of a square matrix, as a vector.", "vector")
def _get_diag(em, args, node):
    m = _matrix(em, args[0], "get_diag", node, square=True)
    return assemble(em, m.type.row_type, _diagonal(em, m, node), node)


@TABLE.define("diag", (1, 1), "The square matrix with vector ``v`` on its diagonal, zeros "
              "elsewhere.", "vector")  # fmt: skip
def _diag(em, args, node):
    v = _vector(em, args[0], "diag", node)
    n, et = v.type.length, v.type.elem
    d = components(em, v, node)
    zero = em.zero(et, node)
    parts = [d[i] if i == j else zero for i in range(n) for j in range(n)]
    return assemble(em, MatrixType(n, n, et), parts, node)


@TABLE.define("skew", (1, 1), "The skew-symmetric matrix of a 3-vector: "
              "``skew(a) @ b == cross(a, b)``.", "vector")  # fmt: skip
def _skew(em, args, node):
    v = _vector(em, args[0], "skew", node)
    if v.type.length != 3:
        raise em.error(KdslTypeError, f"skew() needs a 3-vector, not {v.type}", node)
    x, y, z = components(em, v, node)
    zero = em.zero(v.type.elem, node)

    def neg(c):
        return em.emit("arith.neg", c, node=node)

    parts = [zero, neg(z), y, z, zero, neg(x), neg(y), x, zero]
    return assemble(em, MatrixType(3, 3, v.type.elem), parts, node)


def _dtype(em, x: Any, name: str, node) -> ScalarType:
    try:
        t = public.type_of(x)
    except (TypeError, KeyError):
        t = None
    if not isinstance(t, ScalarType):
        raise em.error(KdslTypeError, f"{name}(): dtype must be a scalar type, not "
                       f"{describe(x)}", node)  # fmt: skip
    return t


def _static_int(em, x: Any, what: str, node) -> int:
    if not (is_weak(x) and isinstance(x, int) and not isinstance(x, bool)) or x < 1:
        raise em.error(KdslTypeError, f"{what} must be a positive integer constant, not "
                       f"{describe(x)}", node)  # fmt: skip
    return x


@TABLE.define("identity", (0, 2), "``identity(n, dtype)``: the n x n identity matrix of ``dtype``.",
              "vector", keywords=("n", "dtype"))  # fmt: skip
def _identity(em, args, node, **kw):
    given = dict(zip(("n", "dtype"), args))
    if set(given) & set(kw):
        raise em.error(KdslTypeError, "identity() got an argument twice", node)
    given.update(kw)
    if "n" not in given:
        raise em.error(KdslTypeError, "identity() needs n (the matrix size)", node)
    n = _static_int(em, given["n"], "identity(): n", node)
    et = _dtype(em, given.get("dtype", float), "identity", node)
    one, zero = em.const(1, et, node), em.zero(et, node)
    parts = [one if i == j else zero for i in range(n) for j in range(n)]
    return assemble(em, MatrixType(n, n, et), parts, node)


def _arg_extreme(name: str, pred: str):
    def lower(em, args, node):
        v = _vector(em, args[0], name, node)
        comps = components(em, v, node)
        is_float = v.type.elem.is_float
        best, idx = comps[0], em.const(0, U32, node)
        for k, c in enumerate(comps[1:], 1):
            take = em.emit("arith.cmp", c, best, node=node, pred=pred)
            if is_float:  # a NaN best is replaced by the first non-NaN component
                best_nan = em.emit("arith.cmp", best, best, node=node, pred="ne")
                c_ok = em.emit("arith.cmp", c, c, node=node, pred="eq")
                take = em.emit("arith.or", take, em.emit("arith.and", best_nan, c_ok, node=node),
                               node=node)  # fmt: skip
            best = em.emit("arith.select", take, c, best, node=node)
            idx = em.emit("arith.select", take, em.const(k, U32, node), idx, node=node)
        return idx

    return lower


TABLE.define("argmin", (1, 1), "Index (uint32) of the smallest component of a vector: the first on "
             "ties; NaN components are skipped (all NaN gives 0).", "vector")(
    _arg_extreme("argmin", "lt"))  # fmt: skip
TABLE.define("argmax", (1, 1), "Index (uint32) of the largest component of a vector: the first on "
             "ties; NaN components are skipped (all NaN gives 0).", "vector")(
    _arg_extreme("argmax", "gt"))  # fmt: skip


@TABLE.define("norm_l1", (1, 1), "L1 norm of a float vector: the sum of ``abs`` of its components.",
              "vector")  # fmt: skip
def _norm_l1(em, args, node):
    v = _vector(em, args[0], "norm_l1", node, float_only=True)
    return _sum(em, components(em, em.emit("math.abs", v, node=node), node), node)


@TABLE.define("norm_l2", (1, 1), "L2 (Euclidean) norm of a float vector; the same as ``length``.",
              "vector")  # fmt: skip
def _norm_l2(em, args, node):
    return em.emit("vec.length", _vector(em, args[0], "norm_l2", node, float_only=True), node=node)


def _vec_delta(em, args, name: str, node) -> tuple[Value, Value]:
    v = _vector(em, args[0], name, node, float_only=True)
    delta = em.value(args[1], node, want=v.type.elem)
    if delta.type != v.type.elem:
        raise em.error(KdslTypeError, f"{name}(): delta must be a {v.type.elem}, not "
                       f"{delta.type}", node)  # fmt: skip
    return v, delta


@TABLE.define("norm_huber", (2, 2), "Huber norm: ``0.5*|v|^2`` if ``|v| <= delta`` else "
              "``delta*(|v| - 0.5*delta)``.", "vector")  # fmt: skip
def _norm_huber(em, args, node):
    v, delta = _vec_delta(em, args, "norm_huber", node)
    n = em.emit("vec.length", v, node=node)
    inner = em.binop("mul", 0.5, em.emit("vec.length_sq", v, node=node), node)
    outer = em.binop("mul", delta, em.binop("sub", n, em.binop("mul", 0.5, delta, node), node),
                     node)  # fmt: skip
    small = em.emit("arith.cmp", n, delta, node=node, pred="le")
    return em.emit("arith.select", small, inner, outer, node=node)


def _pseudo_huber(em, v: Value, delta: Value, node) -> Value:
    d2 = em.binop("mul", delta, delta, node)
    ratio = em.binop("div", em.emit("vec.length_sq", v, node=node), d2, node)
    return em.binop("mul", delta, em.emit("math.sqrt", em.binop("add", 1.0, ratio, node), node=node),
                    node)  # fmt: skip


@TABLE.define("norm_pseudo_huber", (2, 2), "Pseudo-Huber norm (Warp's form): "
              "``delta * sqrt(1 + |v|^2 / delta^2)``.", "vector")  # fmt: skip
def _norm_pseudo_huber(em, args, node):
    v, delta = _vec_delta(em, args, "norm_pseudo_huber", node)
    return _pseudo_huber(em, v, delta, node)


@TABLE.define("smooth_normalize", (2, 2), "``v / norm_pseudo_huber(v, delta)``: a "
              "normalization that is smooth at zero.", "vector")  # fmt: skip
def _smooth_normalize(em, args, node):
    v, delta = _vec_delta(em, args, "smooth_normalize", node)
    return em.emit("arith.div", v, _pseudo_huber(em, v, delta, node), node=node)


def _from_vectors(by_cols: bool):
    what = "matrix_from_cols" if by_cols else "matrix_from_rows"

    def lower(em, args, node):
        vs = [_vector(em, a, what, node) for a in args]
        if any(v.type != vs[0].type for v in vs):
            got = ", ".join(str(v.type) for v in vs)
            raise em.error(KdslTypeError, f"{what}() needs vectors of one type, got {got}", node)
        n, et = vs[0].type.length, vs[0].type.elem
        rows = [components(em, v, node) for v in vs]
        if by_cols:
            parts = [rows[j][i] for i in range(n) for j in range(len(vs))]
            return assemble(em, MatrixType(n, len(vs), et), parts, node)
        return assemble(em, MatrixType(len(vs), n, et), [c for r in rows for c in r], node)

    return lower


TABLE.define("matrix_from_rows", (1, 16), "The matrix whose rows are the given vectors (of one "
             "type).", "vector")(_from_vectors(False))  # fmt: skip
TABLE.define("matrix_from_cols", (1, 16), "The matrix whose columns are the given vectors (of one "
             "type).", "vector")(_from_vectors(True))  # fmt: skip


def _infer_elem(em, args: list[Any], dtype: Any, name: str, node) -> ScalarType:
    if dtype is not None:
        return _dtype(em, dtype, name, node)
    typed = next((a for a in args if isinstance(a, Value)), None)
    if typed is not None:
        return elem_type(typed.type)
    return F32  # weak literals alone: float32, as Warp


@TABLE.define("vector", (0, 64), "``vector(*components, length=n, dtype=t)``: a vector built "
              "in a kernel (zeros without components).", "vector",
              keywords=("length", "dtype"))  # fmt: skip
def _vector_ctor(em, args, node, length: Any = None, dtype: Any = None):
    et = _infer_elem(em, args, dtype, "vector", node)
    if length is None:
        if not args:
            raise em.error(KdslTypeError, "vector() needs components or length=", node)
        length = sum(1 if is_weak(a) else component_count(em.value(a, node).type) for a in args)
    n = _static_int(em, length, "vector(): length", node)
    return em.construct(VectorType(n, et), list(args), node)


@TABLE.define("matrix", (0, 256), "``matrix(*components, shape=(r, c), dtype=t)``: a matrix "
              "built in a kernel (zeros without components).", "vector",
              keywords=("shape", "dtype"))  # fmt: skip
def _matrix_ctor(em, args, node, shape: Any = None, dtype: Any = None):
    if not (isinstance(shape, tuple) and len(shape) == 2):
        raise em.error(KdslTypeError, "matrix() needs shape=(rows, cols) as constants", node)
    r, c = (_static_int(em, s, "matrix(): each shape entry", node) for s in shape)
    et = _infer_elem(em, args, dtype, "matrix", node)
    return em.construct(MatrixType(r, c, et), list(args), node)


# ``wp.vector`` / ``wp.matrix`` are type factories in Python scope, constructors in kernels.
TABLE.alias(public.vector, "vector")
TABLE.alias(public.matrix, "matrix")


# --- stdlib-backed ------------------------------------------------------------------


def _stdlib(module: str, name: str):
    """The ``@kdsl.func`` ``name`` of ``kdsl.stdlib.<module>`` (None if it does not exist)."""
    return getattr(importlib.import_module(f"kdsl.stdlib.{module}"), name, None)


@TABLE.define(
    "determinant", (1, 1), "Determinant of a square 2x2, 3x3 or 4x4 float matrix.", "vector"
)
def _determinant(em, args, node):
    m = _matrix(em, args[0], "determinant", node, square=True)
    require_float(em, m, "determinant", node)
    if m.type.rows > 4:
        raise em.error(
            KdslTypeError, f"determinant() takes 2x2 to 4x4 matrices, not {m.type}", node
        )
    return em.call_user(_stdlib("linalg", "mat_determinant"), [m], node)


# inverse() of each kind of value: (stdlib module, function). Quaternions and
# transforms are checked first: they are VectorType subclasses.
_INVERSES: list[tuple[type, str, str]] = [
    (QuatType, "quat", "quat_inverse"),
    (TransformType, "transform", "transform_inverse"),
    (MatrixType, "linalg", "mat_inverse"),
]


@TABLE.define("inverse", (1, 1), "Inverse of a 2x2, 3x3 or 4x4 float matrix (a singular one, "
              "``determinant == 0``, gives the zero matrix), quaternion or transform.",
              "vector")  # fmt: skip
def _inverse(em, args, node):
    v = em.value(args[0], node) if not is_weak(args[0]) else None
    for cls, module, fname in _INVERSES:
        if v is not None and isinstance(v.type, cls):
            if cls is MatrixType:
                _matrix(em, v, "inverse", node, square=True)
                require_float(em, v, "inverse", node)
                if v.type.rows > 4:
                    raise em.error(KdslTypeError, f"inverse() takes 2x2 to 4x4 matrices, not "
                                   f"{v.type}", node)  # fmt: skip
            fn = _stdlib(module, fname)
            if fn is not None:
                return em.call_user(fn, [v], node)
    got = v.type if v is not None else describe(args[0])
    raise em.error(KdslTypeError, f"inverse() needs a square matrix, quaternion or transform, "
                   f"not {got}", node)  # fmt: skip


TABLE.define("inverse_approx", (1, 1), "The same as ``inverse`` (kdsl computes it exactly on every "
             "backend).", "vector")(_inverse)  # fmt: skip
