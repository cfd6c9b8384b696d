"""The ``vec`` and ``struct`` dialects: composite values kept whole through the passes.

Vectors, matrices, quaternions and transforms are immutable values. ``v[0] = x``
in a kernel becomes ``vec.insert``, which makes a new value. Indices are ``i32``
(or any integer) operands, so dynamic indexing works; constant indices fold.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from kdsl.errors import KdslRuntimeError
from kdsl.ir import semantics as sem
from kdsl.ir.catalog import CATALOG, PURE, SPECULATABLE
from kdsl.ir.types import (
    MatrixType,
    ScalarType,
    StructType,
    Type,
    VectorType,
    elem_type,
    value_shape,
)

_PURE = frozenset({PURE, SPECULATABLE})
# Extract/insert can index out of range: pure, but not speculatable.
_PURE_CHECKED = frozenset({PURE})


def _count(t: Type) -> int:
    return int(np.prod(value_shape(t))) if not isinstance(t, ScalarType) else 1


def _construct_verify(op) -> None:
    rt = op.results[0].type
    if not isinstance(rt, VectorType | MatrixType):
        raise TypeError(f"vec.construct makes a vector or matrix, not {rt}")
    et = elem_type(rt)
    total = 0
    for v in op.operands:
        if not isinstance(v.type, ScalarType | VectorType) or elem_type(v.type) != et:
            raise TypeError(f"cannot build {rt} from a {v.type}: components must be {et}")
        total += _count(v.type)
    if total != _count(rt):
        raise TypeError(f"{rt} has {_count(rt)} components, but {total} were given")


def _construct_interp(ctx, op, *parts):
    rt = op.results[0].type
    flat = np.concatenate([np.ravel(np.asarray(p)) for p in parts])
    return flat.astype(elem_type(rt).np_dtype).reshape(value_shape(rt))


CONSTRUCT = CATALOG.define(
    "vec.construct",
    "A vector or matrix from its components: scalars and vectors concatenated in "
    "row-major order (a matrix may be given as rows).",
    traits=_PURE, verifier=_construct_verify, interp=_construct_interp,
    example="%3 = vec.construct %0, %1, %2 : vec<3, f32>", group="vector",
)  # fmt: skip


def _splat_verify(op) -> None:
    rt = op.results[0].type
    (s,) = op.operands
    if not isinstance(rt, VectorType | MatrixType) or s.type != rt.elem:
        raise TypeError(f"cannot splat {s.type} into {rt}")


def _splat_interp(ctx, op, s):
    rt = op.results[0].type
    return np.full(value_shape(rt), s, dtype=elem_type(rt).np_dtype)


SPLAT = CATALOG.define(
    "vec.splat", "A vector or matrix with every component equal to a scalar.",
    traits=_PURE, verifier=_splat_verify, interp=_splat_interp,
    example="%1 = vec.splat %0 : vec<3, f32>", group="vector",
)  # fmt: skip


def _index_result(t: Type, n_idx: int) -> Type:
    if isinstance(t, MatrixType):
        if n_idx == 1:
            return t.row_type
        if n_idx == 2:
            return t.elem
    elif isinstance(t, VectorType) and n_idx == 1:
        return t.elem
    raise TypeError(f"cannot index a {t} with {n_idx} indices")


def _check_indices(ts: Sequence[Type]) -> None:
    for t in ts:
        if not (isinstance(t, ScalarType) and t.is_int):
            raise TypeError(f"an index must be an integer, not {t}")


def _extract_rule(ts: Sequence[Type], attrs: dict[str, Any]) -> list[Type]:
    _check_indices(ts[1:])
    return [_index_result(ts[0], len(ts) - 1)]


def _checked_index(t: Type, idx: Sequence[Any], loc) -> tuple[int, ...]:
    shape = value_shape(t)
    out = []
    for i, n in zip(idx, shape):
        i = int(i)
        if not 0 <= i < n:
            raise KdslRuntimeError(f"index {i} is out of range for {t} (size {n})", loc)
        out.append(i)
    return tuple(out)


def _extract_interp(ctx, op, v, *idx):
    ix = _checked_index(op.operands[0].type, idx, op.loc)
    r = np.asarray(v)[ix]
    return r.copy() if isinstance(r, np.ndarray) else r


EXTRACT = CATALOG.define(
    "vec.extract",
    "A component of a vector (one index), a row (one index) or an element (two "
    "indices) of a matrix. An index out of range is an error.",
    traits=_PURE_CHECKED, type_rule=_extract_rule, interp=_extract_interp,
    example="%2 = vec.extract %0, %1 : f32", group="vector",
)  # fmt: skip


def _insert_rule(ts: Sequence[Type], attrs: dict[str, Any]) -> list[Type]:
    v, x = ts[0], ts[1]
    _check_indices(ts[2:])
    want = _index_result(v, len(ts) - 2)
    if x != want:
        raise TypeError(f"cannot assign a {x} into a component of {v}: expected {want}")
    return [v]


def _insert_interp(ctx, op, v, x, *idx):
    ix = _checked_index(op.operands[0].type, idx, op.loc)
    out = np.array(v, copy=True)
    out[ix] = x
    return out


INSERT = CATALOG.define(
    "vec.insert",
    "A copy of a vector or matrix with one component (or matrix row) replaced.",
    traits=_PURE_CHECKED, type_rule=_insert_rule, interp=_insert_interp,
    example="%3 = vec.insert %0, %1, %2 : vec<3, f32>", group="vector",
)  # fmt: skip


def _same_vectors(name: str, length: int | None = None):
    def check(ts: Sequence[Type]) -> VectorType:
        a = ts[0]
        if any(t != a for t in ts) or not isinstance(a, VectorType):
            got = ", ".join(map(str, ts))
            raise TypeError(f"{name}() needs vectors of one type, got {got}")
        if length is not None and a.length != length:
            raise TypeError(f"{name}() needs {length}-vectors, not {a}")
        return a

    return check


def _float_vec(name: str, t: VectorType) -> None:
    if not t.elem.is_float:
        raise TypeError(f"{name}() needs a float vector, not {t}")


def _rule(fn):
    def rule(ts: Sequence[Type], attrs: dict[str, Any]) -> list[Type]:
        return [fn(ts)]

    return rule


def _interp(fn):
    def interp(ctx, op, *args):
        with np.errstate(all="ignore"):
            dt = elem_type(op.results[0].type).np_dtype
            return sem.unwrap(np.asarray(fn(*[np.asarray(a) for a in args])).astype(dt))

    return interp


def _dot_type(ts):
    return _same_vectors("dot")(ts).elem


def _cross_type(ts):
    return _same_vectors("cross", 3)(ts)


def _length_type(ts):
    t = _same_vectors("length")(ts)
    _float_vec("length", t)
    return t.elem


def _normalize_type(ts):
    t = _same_vectors("normalize")(ts)
    _float_vec("normalize", t)
    return t


def _normalize(v):
    n = np.sqrt(np.sum(v * v))
    return v / n if n > 0 else np.zeros_like(v)


def _matmul_type(ts):
    a, b = ts
    same_elem = elem_type(a) == elem_type(b) if a.is_value and b.is_value else False
    if same_elem and isinstance(a, MatrixType) and isinstance(b, MatrixType) and a.cols == b.rows:
        return MatrixType(a.rows, b.cols, a.elem)
    if same_elem and isinstance(a, MatrixType) and isinstance(b, VectorType) and a.cols == b.length:
        return VectorType(a.rows, a.elem)
    if same_elem and isinstance(a, VectorType) and isinstance(b, MatrixType) and a.length == b.rows:
        return VectorType(b.cols, a.elem)
    raise TypeError(f"cannot multiply {a} by {b}: shapes or element types do not match")


def _transpose_type(ts):
    (a,) = ts
    if not isinstance(a, MatrixType):
        raise TypeError(f"transpose() needs a matrix, not {a}")
    return MatrixType(a.cols, a.rows, a.elem)


def _outer_type(ts):
    a, b = ts
    if not (isinstance(a, VectorType) and isinstance(b, VectorType) and a.elem == b.elem):
        raise TypeError(f"outer() needs two vectors of one element type, got {a} and {b}")
    return MatrixType(a.length, b.length, a.elem)


_LINALG = [
    ("dot", _dot_type, lambda a, b: np.sum(a * b), "Dot product of two vectors.",
     "%2 = vec.dot %0, %1 : f32"),
    ("cross", _cross_type, np.cross, "Cross product of two 3-vectors.",
     "%2 = vec.cross %0, %1 : vec<3, f32>"),
    ("length", _length_type, lambda v: np.sqrt(np.sum(v * v)), "Euclidean length.",
     "%1 = vec.length %0 : f32"),
    ("length_sq", lambda ts: _same_vectors("length_sq")(ts).elem, lambda v: np.sum(v * v),
     "Squared Euclidean length.", "%1 = vec.length_sq %0 : f32"),
    ("normalize", _normalize_type, _normalize,
     "The vector divided by its length; the zero vector stays zero.",
     "%1 = vec.normalize %0 : vec<3, f32>"),
    ("matmul", _matmul_type, np.matmul,
     "Matrix product: matrix x matrix, matrix x vector, or vector x matrix.",
     "%2 = vec.matmul %0, %1 : vec<3, f32>"),
    ("transpose", _transpose_type, np.transpose, "Matrix transpose.",
     "%1 = vec.transpose %0 : mat<3, 3, f32>"),
    ("outer", _outer_type, np.outer, "Outer product of two vectors.",
     "%2 = vec.outer %0, %1 : mat<3, 3, f32>"),
]  # fmt: skip

for _name, _type_fn, _fn, _doc, _example in _LINALG:
    CATALOG.define(
        f"vec.{_name}", _doc, traits=_PURE, type_rule=_rule(_type_fn), interp=_interp(_fn),
        example=_example, group="vector",
    )  # fmt: skip


# --- structs ---------------------------------------------------------------


def _struct_construct_verify(op) -> None:
    st = op.results[0].type
    if not isinstance(st, StructType):
        raise TypeError(f"struct.construct makes a struct, not {st}")
    got = [v.type for v in op.operands]
    want = [t for _, t in st.fields]
    if got != want:
        raise TypeError(
            f"struct {st.name} needs fields ({', '.join(map(str, want))}), "
            f"got ({', '.join(map(str, got))})"
        )


STRUCT_CONSTRUCT = CATALOG.define(
    "struct.construct", "A struct value from all of its fields, in order.",
    traits=_PURE, verifier=_struct_construct_verify,
    interp=lambda ctx, op, *fields: tuple(fields),
    example="%2 = struct.construct %0, %1 : struct<Particle>", group="struct",
)  # fmt: skip


def _field_type(st: Type, attrs: dict[str, Any]) -> Type:
    if not isinstance(st, StructType):
        raise TypeError(f"only structs have fields, not {st}")
    name = attrs.get("field")
    try:
        return st.field_type(name)
    except KeyError:
        fields = ", ".join(n for n, _ in st.fields)
        raise TypeError(f"struct {st.name} has no field {name!r} (it has: {fields})") from None


def _struct_extract_rule(ts: Sequence[Type], attrs: dict[str, Any]) -> list[Type]:
    return [_field_type(ts[0], attrs)]


def _struct_insert_rule(ts: Sequence[Type], attrs: dict[str, Any]) -> list[Type]:
    want = _field_type(ts[0], attrs)
    if ts[1] != want:
        raise TypeError(f"cannot assign a {ts[1]} to field {attrs['field']!r} of type {want}")
    return [ts[0]]


def _struct_extract_interp(ctx, op, s):
    return s[op.operands[0].type.field_index(op.attrs["field"])]


def _struct_insert_interp(ctx, op, s, x):
    i = op.operands[0].type.field_index(op.attrs["field"])
    return s[:i] + (x,) + s[i + 1 :]


STRUCT_EXTRACT = CATALOG.define(
    "struct.extract", "One field of a struct value.",
    traits=_PURE, type_rule=_struct_extract_rule, interp=_struct_extract_interp,
    required_attrs=("field",),
    example='%1 = struct.extract %0 {field = "x"} : vec<3, f32>', group="struct",
)  # fmt: skip
STRUCT_INSERT = CATALOG.define(
    "struct.insert", "A copy of a struct with one field replaced.",
    traits=_PURE, type_rule=_struct_insert_rule, interp=_struct_insert_interp,
    required_attrs=("field",),
    example='%2 = struct.insert %0, %1 {field = "x"} : struct<Particle>', group="struct",
)  # fmt: skip
