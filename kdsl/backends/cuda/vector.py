"""Lowerings of the ``vec`` and ``struct`` dialects.

Vectors and matrices are small structs (``ctypes_``); components are ``v.c[i]``
with possibly dynamic indices (not range-checked in release mode, as on cpu).
Linear algebra ops call a helper generated per op and type, computing in the
element type (float16: in float, rounded once at the end, as the cpu backend
does) and summing left to right, so results match the cpu backend.
"""

from __future__ import annotations

from kdsl.backends.cuda import ctypes_ as CT
from kdsl.backends.cuda.arith import is_f16, scalar_rule
from kdsl.backends.cuda.emitter import FuncEmitter, Source
from kdsl.ir import types as T
from kdsl.ir.core import Operation
from kdsl.ir.lowering import LOWERINGS

CUDA = LOWERINGS.for_backend("cuda")

_FI = "__device__ __forceinline__"


def _lanes(em: FuncEmitter, v, t: T.Type) -> list[str]:
    if isinstance(t, T.ScalarType):
        return [v]
    return [f"{v}.c[{i}]" for i in range(CT.count(t))]


def _construct(em: FuncEmitter, op: Operation) -> str:
    parts = [x for v in op.operands for x in _lanes(em, em.get(v), v.type)]
    return f"{em.ctype(op.results[0].type)}{{{{{', '.join(parts)}}}}}"


def _splat(em: FuncEmitter, op: Operation) -> str:
    rt = op.results[0].type
    s = em.get(op.operands[0])
    return f"{em.ctype(rt)}{{{{{', '.join([s] * CT.count(rt))}}}}}"


def _extract(em: FuncEmitter, op: Operation) -> str:
    t = op.operands[0].type
    v = em.get(op.operands[0])
    idx = [em.get(i) for i in op.operands[1:]]
    if isinstance(t, T.MatrixType):
        if len(idx) == 2:
            return f"{v}.c[{idx[0]} * {t.cols} + {idx[1]}]"
        row = ", ".join(f"{v}.c[{idx[0]} * {t.cols} + {j}]" for j in range(t.cols))
        return f"{em.ctype(t.row_type)}{{{{{row}}}}}"
    return f"{v}.c[{idx[0]}]"


def _insert(em: FuncEmitter, op: Operation) -> str:
    t = op.operands[0].type
    v, x = em.get(op.operands[0]), em.get(op.operands[1])
    idx = [em.get(i) for i in op.operands[2:]]
    r = em.declare(t, v)
    if isinstance(t, T.MatrixType) and len(idx) == 1:
        for j in range(t.cols):
            em.line(f"{r}.c[{idx[0]} * {t.cols} + {j}] = {x}.c[{j}];")
    elif isinstance(t, T.MatrixType):
        em.line(f"{r}.c[{idx[0]} * {t.cols} + {idx[1]}] = {x};")
    else:
        em.line(f"{r}.c[{idx[0]}] = {x};")
    return r


class _Math:
    """Scalar C arithmetic in an op's compute type (float for float16 values)."""

    def __init__(self, src: Source, et: T.ScalarType) -> None:
        self.src = src
        self.et = et
        self.ct = T.F32 if is_f16(et) else et
        self.c = CT.scalar_c(self.ct)

    def ld(self, x: str) -> str:
        return f"kd_h2f({x})" if is_f16(self.et) else x

    def st(self, x: str) -> str:
        return f"kd_f2h({x})" if is_f16(self.et) else x

    def op(self, kind: str, a: str, b: str) -> str:
        return scalar_rule(kind, self.ct)(self.src, self.ct, a, b)

    def dot(self, a: list[str], b: list[str]) -> str:
        """Sum of products, left to right, in the compute type."""
        acc = self.op("mul", self.ld(a[0]), self.ld(b[0]))
        for x, y in zip(a[1:], b[1:]):
            acc = self.op("add", acc, self.op("mul", self.ld(x), self.ld(y)))
        return acc

    def sqrt(self, x: str) -> str:
        return f"{'sqrtf' if self.ct.bits == 32 else 'sqrt'}({x})"


def _helper(em: FuncEmitter, op: Operation, name: str, body) -> str:
    """Call the helper ``name`` for ``op``'s operand types, generating it on first use.

    ``body(m, a, b)`` returns the C statements computing ``r`` (or the result expression).
    """
    rt = op.results[0].type
    ts = [v.type for v in op.operands]
    et = T.elem_type(ts[0])
    rc = em.ctype(rt)
    params = ", ".join(f"{em.ctype(t)} {n}" for t, n in zip(ts, "ab"))
    key = f"fn:{name}({params})"

    def make() -> str:
        m = _Math(em.src, et)
        text = body(m, *ts)
        return f"{_FI} {rc} {name}({params}) {{\n{text}\n}}"

    em.src.need(key, make)
    return f"{name}({', '.join(em.args(op))})"


def _la(t: T.Type, v: str) -> list[str]:
    return [f"{v}.c[{i}]" for i in range(CT.count(t))]


def _dot(em: FuncEmitter, op: Operation) -> str:
    return _helper(em, op, "kd_dot", lambda m, ta, tb: (
        f"  return {m.st(m.dot(_la(ta, 'a'), _la(tb, 'b')))};"))  # fmt: skip


def _length_sq(em: FuncEmitter, op: Operation) -> str:
    return _helper(em, op, "kd_length_sq", lambda m, ta: (
        f"  return {m.st(m.dot(_la(ta, 'a'), _la(ta, 'a')))};"))  # fmt: skip


def _length(em: FuncEmitter, op: Operation) -> str:
    return _helper(em, op, "kd_length", lambda m, ta: (
        f"  return {m.st(m.sqrt(m.dot(_la(ta, 'a'), _la(ta, 'a'))))};"))  # fmt: skip


def _normalize(em: FuncEmitter, op: Operation) -> str:
    rc = em.ctype(op.results[0].type)

    def body(m: _Math, ta: T.Type) -> str:
        n = CT.count(ta)
        zero = "kd_f16{0}" if is_f16(m.et) else f"({m.c})0"
        return (
            f"  {m.c} n = {m.sqrt(m.dot(_la(ta, 'a'), _la(ta, 'a')))};\n  {rc} r;\n"
            f"  for (int i = 0; i < {n}; ++i) r.c[i] = n > ({m.c})0 ? "
            f"{m.st(m.op('div', m.ld('a.c[i]'), 'n'))} : {zero};\n  return r;"
        )

    return _helper(em, op, "kd_normalize", body)


def _cross(em: FuncEmitter, op: Operation) -> str:
    rc = em.ctype(op.results[0].type)

    def body(m: _Math, ta: T.Type, tb: T.Type) -> str:
        a, b = [m.ld(f"a.c[{i}]") for i in range(3)], [m.ld(f"b.c[{i}]") for i in range(3)]
        lanes = [
            m.st(m.op("sub", m.op("mul", a[i], b[j]), m.op("mul", a[j], b[i])))
            for i, j in ((1, 2), (2, 0), (0, 1))
        ]
        return f"  return {rc}{{{{{', '.join(lanes)}}}}};"

    return _helper(em, op, "kd_cross", body)


def _matmul(em: FuncEmitter, op: Operation) -> str:
    rc = em.ctype(op.results[0].type)
    ta, tb = op.operands[0].type, op.operands[1].type
    rows = ta.rows if isinstance(ta, T.MatrixType) else 1
    inner = ta.cols if isinstance(ta, T.MatrixType) else ta.length
    cols = tb.cols if isinstance(tb, T.MatrixType) else 1

    def body(m: _Math, ta: T.Type, tb: T.Type) -> str:
        out = []
        for i in range(rows):
            for j in range(cols):
                a = [f"a.c[{i * inner + k}]" for k in range(inner)]
                b = [f"b.c[{k * cols + j}]" for k in range(inner)]
                out.append(m.st(m.dot(a, b)))
        return f"  return {rc}{{{{{', '.join(out)}}}}};"

    return _helper(em, op, "kd_matmul", body)


def _transpose(em: FuncEmitter, op: Operation) -> str:
    t = op.operands[0].type
    (a,) = em.args(op)
    lanes = [f"{a}.c[{j * t.cols + i}]" for i in range(t.cols) for j in range(t.rows)]
    return f"{em.ctype(op.results[0].type)}{{{{{', '.join(lanes)}}}}}"


def _outer(em: FuncEmitter, op: Operation) -> str:
    rc = em.ctype(op.results[0].type)

    def body(m: _Math, ta: T.Type, tb: T.Type) -> str:
        out = [
            m.st(m.op("mul", m.ld(f"a.c[{i}]"), m.ld(f"b.c[{j}]")))
            for i in range(ta.length)
            for j in range(tb.length)
        ]
        return f"  return {rc}{{{{{', '.join(out)}}}}};"

    return _helper(em, op, "kd_outer", body)


def _struct_construct(em: FuncEmitter, op: Operation) -> str:
    return f"{em.ctype(op.results[0].type)}{{{', '.join(em.args(op))}}}"


def _struct_extract(em: FuncEmitter, op: Operation) -> str:
    i = op.operands[0].type.field_index(op.attrs["field"])
    return f"{em.get(op.operands[0])}.f{i}"


def _struct_insert(em: FuncEmitter, op: Operation) -> str:
    t = op.operands[0].type
    i = t.field_index(op.attrs["field"])
    s, x = em.args(op)
    r = em.declare(t, s)
    em.line(f"{r}.f{i} = {x};")
    return r


CUDA.register("vec.construct", _construct)
CUDA.register("vec.splat", _splat)
CUDA.register("vec.extract", _extract)
CUDA.register("vec.insert", _insert)
CUDA.register("vec.dot", _dot)
CUDA.register("vec.cross", _cross)
CUDA.register("vec.length", _length)
CUDA.register("vec.length_sq", _length_sq)
CUDA.register("vec.normalize", _normalize)
CUDA.register("vec.matmul", _matmul)
CUDA.register("vec.transpose", _transpose)
CUDA.register("vec.outer", _outer)
CUDA.register("struct.construct", _struct_construct)
CUDA.register("struct.extract", _struct_extract)
CUDA.register("struct.insert", _struct_insert)
