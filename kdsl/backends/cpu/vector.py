"""Lowerings of the ``vec`` and ``struct`` dialects.

Vectors and matrices are LLVM vectors (matrices flattened row-major), so
components are ``extractelement``/``insertelement`` with possibly dynamic indices,
and fixed permutations (transpose, cross) are ``shufflevector``. Dynamic indices
are not range-checked (release mode); the interp backend checks them.
"""

from __future__ import annotations

from collections.abc import Callable

from llvmlite import ir

from kdsl.backends.cpu import types as LT
from kdsl.backends.cpu.arith import widen_half
from kdsl.backends.cpu.emitter import Emitter, I32c, Lowering
from kdsl.ir import types as T
from kdsl.ir.core import Operation, Value


def _lanes(em: Emitter, v: ir.Value) -> list[ir.Value]:
    if not isinstance(v.type, ir.VectorType):
        return [v]
    return [em.b.extract_element(v, I32c(i)) for i in range(v.type.count)]


def build(em: Emitter, t: ir.VectorType, parts: list[ir.Value]) -> ir.Value:
    """A vector of type ``t`` from its scalar lanes."""
    out = ir.Constant(t, ir.Undefined)
    for i, p in enumerate(parts):
        out = em.b.insert_element(out, p, I32c(i))
    return out


def _shuffle(em: Emitter, v: ir.Value, mask: list[int]) -> ir.Value:
    m = ir.Constant(ir.VectorType(LT.I32, len(mask)), mask)
    return em.b.shuffle_vector(v, ir.Constant(v.type, ir.Undefined), m)


def _construct(em: Emitter, op: Operation) -> ir.Value:
    parts = [lane for v in em.args(op) for lane in _lanes(em, v)]
    return build(em, LT.llvm_type(op.results[0].type), parts)


def _splat(em: Emitter, op: Operation) -> ir.Value:
    (s,) = em.args(op)
    return em.splat(s, LT.llvm_type(op.results[0].type))


def _flat_index(em: Emitter, t: T.Type, idx: list[Value]) -> ir.Value:
    """Lane of element ``idx`` (one index of a vector, two of a matrix), as i64."""
    vals = []
    for v in idx:
        x = em.get(v)
        if v.type.bits < 64:
            x = em.b.sext(x, LT.I64) if v.type.is_signed else em.b.zext(x, LT.I64)
        vals.append(x)
    if len(vals) == 1:
        return vals[0]
    row = em.b.mul(vals[0], ir.Constant(LT.I64, t.cols))
    return em.b.add(row, vals[1])


def _row_lanes(em: Emitter, t: T.MatrixType, row: Value) -> list[ir.Value]:
    base = _flat_index(em, t, [row])
    base = em.b.mul(base, ir.Constant(LT.I64, t.cols))
    return [em.b.add(base, ir.Constant(LT.I64, j)) for j in range(t.cols)]


def _extract(em: Emitter, op: Operation) -> ir.Value:
    t = op.operands[0].type
    v, idx = em.get(op.operands[0]), op.operands[1:]
    if isinstance(t, T.MatrixType) and len(idx) == 1:
        lanes = [em.b.extract_element(v, i) for i in _row_lanes(em, t, idx[0])]
        return build(em, LT.llvm_type(t.row_type), lanes)
    return em.b.extract_element(v, _flat_index(em, t, idx))


def _insert(em: Emitter, op: Operation) -> ir.Value:
    t = op.operands[0].type
    v, x, idx = em.get(op.operands[0]), em.get(op.operands[1]), op.operands[2:]
    if isinstance(t, T.MatrixType) and len(idx) == 1:
        for j, lane in enumerate(_row_lanes(em, t, idx[0])):
            v = em.b.insert_element(v, em.b.extract_element(x, I32c(j)), lane)
        return v
    return em.b.insert_element(v, x, _flat_index(em, t, idx))


def _num(em: Emitter, et: T.ScalarType) -> tuple[Callable, Callable]:
    """(add, mul) emitters for element type ``et``."""
    if et.is_float:
        return em.b.fadd, em.b.fmul
    return em.b.add, em.b.mul


def _sum(em: Emitter, et: T.ScalarType, lanes: list[ir.Value]) -> ir.Value:
    add, _ = _num(em, et)
    acc = lanes[0]
    for x in lanes[1:]:
        acc = add(acc, x)
    return acc


def dot(em: Emitter, et: T.ScalarType, a: ir.Value, b: ir.Value) -> ir.Value:
    """Dot product, summed left to right."""
    _, mul = _num(em, et)
    return _sum(em, et, _lanes(em, mul(a, b)))


def _widened(fn: Callable) -> Lowering:
    """A lowering ``fn(em, et, *args)`` computed in float32 for float16 values."""

    def lower(em: Emitter, op: Operation) -> ir.Value:
        et = T.elem_type(op.results[0].type)
        return widen_half(em, et, lambda *xs: fn(em, et, op, *xs), *em.args(op))

    return lower


def _dot(em, et, op, a, b):
    return dot(em, et, a, b)


def _length_sq(em, et, op, a):
    return dot(em, et, a, a)


def _length(em, et, op, a):
    return em.call_intrinsic("llvm.sqrt", dot(em, et, a, a))


def _normalize(em, et, op, a):
    n = em.call_intrinsic("llvm.sqrt", dot(em, et, a, a))
    pos = em.b.fcmp_ordered(">", n, em.const(n.type, 0.0))
    q = em.b.fdiv(a, em.splat(n, a.type))
    return em.b.select(pos, q, em.const(a.type, 0.0))


def _cross(em, et, op, a, b):
    _, mul = _num(em, et)
    sub = em.b.fsub if et.is_float else em.b.sub
    yzx, zxy = [1, 2, 0], [2, 0, 1]
    left = mul(_shuffle(em, a, yzx), _shuffle(em, b, zxy))
    return sub(left, mul(_shuffle(em, a, zxy), _shuffle(em, b, yzx)))


def _matmul(em, et, op, a, b):
    ta, tb = op.operands[0].type, op.operands[1].type
    # (rows, inner, cols) of the product, vectors taken as 1 x n or n x 1.
    rows = ta.rows if isinstance(ta, T.MatrixType) else 1
    inner = ta.cols if isinstance(ta, T.MatrixType) else ta.length
    cols = tb.cols if isinstance(tb, T.MatrixType) else 1
    la, lb = _lanes(em, a), _lanes(em, b)
    _, mul = _num(em, et)
    out = []
    for i in range(rows):
        for j in range(cols):
            out.append(
                _sum(em, et, [mul(la[i * inner + k], lb[k * cols + j]) for k in range(inner)])
            )
    rt = LT.llvm_type(op.results[0].type)
    return build(em, ir.VectorType(la[0].type, rt.count), out)


def _transpose(em: Emitter, op: Operation) -> ir.Value:
    t = op.operands[0].type
    (a,) = em.args(op)
    return _shuffle(em, a, [j * t.cols + i for i in range(t.cols) for j in range(t.rows)])


def _outer(em, et, op, a, b):
    n, m = a.type.count, b.type.count
    _, mul = _num(em, et)
    left = _shuffle(em, a, [i for i in range(n) for _ in range(m)])
    right = _shuffle(em, b, [j for _ in range(n) for j in range(m)])
    return mul(left, right)


def _struct_construct(em: Emitter, op: Operation) -> ir.Value:
    out = ir.Constant(LT.llvm_type(op.results[0].type), ir.Undefined)
    for i, v in enumerate(em.args(op)):
        out = em.b.insert_value(out, v, i)
    return out


def _struct_extract(em: Emitter, op: Operation) -> ir.Value:
    i = op.operands[0].type.field_index(op.attrs["field"])
    return em.b.extract_value(em.get(op.operands[0]), i)


def _struct_insert(em: Emitter, op: Operation) -> ir.Value:
    i = op.operands[0].type.field_index(op.attrs["field"])
    s, x = em.args(op)
    return em.b.insert_value(s, x, i)


TABLE: dict[str, Lowering] = {
    "vec.construct": _construct,
    "vec.splat": _splat,
    "vec.extract": _extract,
    "vec.insert": _insert,
    "vec.dot": _widened(_dot),
    "vec.cross": _widened(_cross),
    "vec.length": _widened(_length),
    "vec.length_sq": _widened(_length_sq),
    "vec.normalize": _widened(_normalize),
    "vec.matmul": _widened(_matmul),
    "vec.transpose": _transpose,
    "vec.outer": _widened(_outer),
    "struct.construct": _struct_construct,
    "struct.extract": _struct_extract,
    "struct.insert": _struct_insert,
}
