"""Lowerings of the ``vec`` and ``struct`` dialects, on scalarized values.

A vector or matrix value is a ``composite.Parts`` of its scalar components
(matrices row-major), a struct a ``Parts`` of its fields, so these lowerings are
plain bookkeeping on Python lists plus scalar arithmetic. Constant indices (the
usual case after constant folding) pick a component directly; a dynamic index
picks it with a chain of selects (vectorizable, unlike a spill to memory). Dynamic
indices are not range-checked (release mode): an out-of-range one picks an
arbitrary component. The interp backend checks them.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from llvmlite import ir

from kdsl.backends.cpu import types as LT
from kdsl.backends.cpu.arith import widen_half
from kdsl.backends.cpu.composite import Parts, components
from kdsl.backends.cpu.emitter import Emitter, Lowering
from kdsl.ir import types as T
from kdsl.ir.core import Operation, Value
from kdsl.ir.lowering import LOWERINGS

CPU = LOWERINGS.for_backend("cpu")


def _construct(em: Emitter, op: Operation) -> Parts:
    return Parts(x for v in em.args(op) for x in components(v))


def _splat(em: Emitter, op: Operation) -> Parts:
    (s,) = em.args(op)
    return Parts([s] * LT.count(op.results[0].type))


def _index(em: Emitter, v: Value) -> int | ir.Value:
    """Index ``v`` as a Python int when it is a constant, else as an i64 value."""
    x = em.get(v)
    if isinstance(x, ir.Constant) and isinstance(x.constant, int):
        c = x.constant
        if not v.type.is_signed and c < 0:  # unsigned constants above the signed range
            c += 1 << v.type.bits
        return c
    if v.type.bits < 64:
        x = em.b.sext(x, LT.I64) if v.type.is_signed else em.b.zext(x, LT.I64)
    return x


def _flat_index(em: Emitter, t: T.Type, idx: list[Value]) -> int | ir.Value:
    """Component number of element ``idx`` (one index of a vector, two of a matrix)."""
    vals = [_index(em, v) for v in idx]
    if len(vals) == 1:
        return vals[0]
    i, j = vals
    if isinstance(i, int) and isinstance(j, int):
        return i * t.cols + j
    i, j = (ir.Constant(LT.I64, x) if isinstance(x, int) else x for x in (i, j))
    return em.b.add(em.b.mul(i, ir.Constant(LT.I64, t.cols)), j)


def _is_lane(em: Emitter, k: int | ir.Value, lane: int) -> ir.Value:
    """i1: the dynamic component number ``k`` is ``lane``."""
    return em.b.icmp_unsigned("==", k, ir.Constant(LT.I64, lane))


def _pick(em: Emitter, comps: list[ir.Value], k: int | ir.Value) -> ir.Value:
    """Component ``k`` of ``comps`` (a constant or dynamic component number)."""
    if isinstance(k, int):
        if 0 <= k < len(comps):
            return comps[k]
        return ir.Constant(comps[0].type, ir.Undefined)
    out = comps[0]
    for lane in range(1, len(comps)):
        out = em.b.select(_is_lane(em, k, lane), comps[lane], out)
    return out


def _put(em: Emitter, comps: list[ir.Value], k: int | ir.Value, x: ir.Value) -> list[ir.Value]:
    """``comps`` with component ``k`` replaced by ``x``."""
    if isinstance(k, int):
        return [x if lane == k else c for lane, c in enumerate(comps)]
    return [em.b.select(_is_lane(em, k, lane), x, c) for lane, c in enumerate(comps)]


def _row_numbers(em: Emitter, t: T.MatrixType, row: Value) -> list[int | ir.Value]:
    """The component numbers of row ``row`` of a matrix of type ``t``."""
    r = _index(em, row)
    if isinstance(r, int):
        return [r * t.cols + j for j in range(t.cols)]
    base = em.b.mul(r, ir.Constant(LT.I64, t.cols))
    return [em.b.add(base, ir.Constant(LT.I64, j)) for j in range(t.cols)]


def _extract(em: Emitter, op: Operation) -> Any:
    t = op.operands[0].type
    comps, idx = em.get(op.operands[0]).items, op.operands[1:]
    if isinstance(t, T.MatrixType) and len(idx) == 1:
        return Parts(_pick(em, comps, k) for k in _row_numbers(em, t, idx[0]))
    return _pick(em, comps, _flat_index(em, t, idx))


def _insert(em: Emitter, op: Operation) -> Parts:
    t = op.operands[0].type
    comps, x, idx = em.get(op.operands[0]).items, em.get(op.operands[1]), op.operands[2:]
    if isinstance(t, T.MatrixType) and len(idx) == 1:
        for k, xj in zip(_row_numbers(em, t, idx[0]), x.items):
            comps = _put(em, comps, k, xj)
        return Parts(comps)
    return Parts(_put(em, comps, _flat_index(em, t, idx), x))


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


def dot(em: Emitter, et: T.ScalarType, a: Parts, b: Parts) -> ir.Value:
    """Dot product, summed left to right."""
    _, mul = _num(em, et)
    return _sum(em, et, [mul(x, y) for x, y in zip(a, b)])


def _widened(fn: Callable) -> Lowering:
    """A lowering ``fn(em, et, op, *args)`` computed in float32 for float16 values."""

    def lower(em: Emitter, op: Operation) -> Any:
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
    zero = em.const(n.type, 0.0)
    return em.map(lambda x: em.b.select(pos, em.b.fdiv(x, n), zero), a)


def _cross(em, et, op, a, b):
    _, mul = _num(em, et)
    sub = em.b.fsub if et.is_float else em.b.sub
    yzx, zxy = [1, 2, 0], [2, 0, 1]
    return Parts(sub(mul(a[yzx[i]], b[zxy[i]]), mul(a[zxy[i]], b[yzx[i]])) for i in range(3))


def _matmul(em, et, op, a, b):
    ta, tb = op.operands[0].type, op.operands[1].type
    # (rows, inner, cols) of the product, vectors taken as 1 x n or n x 1.
    rows = ta.rows if isinstance(ta, T.MatrixType) else 1
    inner = ta.cols if isinstance(ta, T.MatrixType) else ta.length
    cols = tb.cols if isinstance(tb, T.MatrixType) else 1
    _, mul = _num(em, et)
    out = []
    for i in range(rows):
        for j in range(cols):
            out.append(_sum(em, et, [mul(a[i * inner + k], b[k * cols + j]) for k in range(inner)]))
    return Parts(out)


def _transpose(em: Emitter, op: Operation) -> Parts:
    t = op.operands[0].type
    (a,) = em.args(op)
    return Parts(a[j * t.cols + i] for i in range(t.cols) for j in range(t.rows))


def _outer(em, et, op, a, b):
    _, mul = _num(em, et)
    return Parts(mul(x, y) for x in a for y in b)


def _struct_construct(em: Emitter, op: Operation) -> Parts:
    return Parts(em.args(op))


def _struct_extract(em: Emitter, op: Operation) -> Any:
    i = op.operands[0].type.field_index(op.attrs["field"])
    return em.get(op.operands[0])[i]


def _struct_insert(em: Emitter, op: Operation) -> Parts:
    i = op.operands[0].type.field_index(op.attrs["field"])
    s, x = em.args(op)
    fields = list(s.items)
    fields[i] = x
    return Parts(fields)


CPU.register("vec.construct", _construct)
CPU.register("vec.splat", _splat)
CPU.register("vec.extract", _extract)
CPU.register("vec.insert", _insert)
CPU.register("vec.dot", _widened(_dot))
CPU.register("vec.cross", _widened(_cross))
CPU.register("vec.length", _widened(_length))
CPU.register("vec.length_sq", _widened(_length_sq))
CPU.register("vec.normalize", _widened(_normalize))
CPU.register("vec.matmul", _widened(_matmul))
CPU.register("vec.transpose", _transpose)
CPU.register("vec.outer", _widened(_outer))
CPU.register("struct.construct", _struct_construct)
CPU.register("struct.extract", _struct_extract)
CPU.register("struct.insert", _struct_insert)
