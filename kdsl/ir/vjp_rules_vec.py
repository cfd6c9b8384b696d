"""VJP rules of the ``vec`` and ``struct`` dialects (see ``kdsl.ir.vjp``).

Index operands (which may be dynamic ``i32`` values) get no adjoint; an extract's
adjoint is an insert into zeros at the same primal index, and the reverse. A
struct's adjoint is a struct of the same type whose non-float fields are zero;
fields that have no zero value (arrays, handles) carry the primal field instead,
which no one reads as an adjoint.
"""

from __future__ import annotations

from collections.abc import Sequence

from kdsl.ir.core import Operation, Value
from kdsl.ir.types import MatrixType, StructType, Type, VectorType
from kdsl.ir.vjp import VjpContext, is_differentiable
from kdsl.ir.vjp_helpers import assemble, components, rule, scale, sum_product

Adj = Sequence["Value | None"]


@rule("vec.construct")
def _construct(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """Each part gets its slice of the adjoint (row-major). Linear."""
    (g,) = adj
    rt = g.type
    cols = rt.cols if isinstance(rt, MatrixType) else None
    out: list[Value | None] = []
    offset = 0
    flat: list[Value] | None = None
    for part in op.operands:
        t = part.type
        n = t.length if isinstance(t, VectorType) else 1
        if cols is not None and n == cols and offset % cols == 0 and isinstance(t, VectorType):
            out.append(ctx.extract(g, offset // cols))  # a whole row
        elif n == 1 and not isinstance(t, VectorType):
            out.append(ctx.extract(g, *_flat_index(rt, offset)))
        else:
            if flat is None:
                flat = components(ctx, g)
            out.append(assemble(ctx, flat[offset : offset + n], t))
        offset += n
    return out


def _flat_index(t: Type, k: int) -> tuple[int, ...]:
    """The constant indices of row-major component ``k`` of a vector or matrix."""
    if isinstance(t, MatrixType):
        return divmod(k, t.cols)
    return (k,)


@rule("vec.splat")
def _splat(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """The scalar gets the sum of the adjoint's components. Linear."""
    (g,) = adj
    return [sum_product(ctx, g, ctx.const(1, g.type))]


@rule("vec.extract")
def _extract(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """The vector gets the adjoint inserted into zeros at the same index. Linear."""
    (g,) = adj
    v, *idx = ctx.operands(op)
    return [ctx.emit("vec.insert", ctx.zeros(v.type), g, *idx), *[None] * len(idx)]


@rule("vec.insert")
def _insert(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """The vector gets the adjoint with the slot zeroed; the new part gets the slot. Linear."""
    (g,) = adj
    _v, x, *idx = ctx.operands(op)
    adj_v = ctx.emit("vec.insert", g, ctx.zeros(x.type), *idx)
    adj_x = ctx.emit("vec.extract", g, *idx)
    return [adj_v, adj_x, *[None] * len(idx)]


@rule("vec.dot")
def _dot(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """d(a.b) = b da + a db. Smooth everywhere."""
    (g,) = adj
    a, b = ctx.operands(op)
    return [ctx.mul(g, b), ctx.mul(g, a)]


@rule("vec.cross")
def _cross(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """c = a x b: a gets b x g, b gets g x a. Smooth everywhere."""
    (g,) = adj
    a, b = ctx.operands(op)
    return [ctx.emit("vec.cross", b, g), ctx.emit("vec.cross", g, a)]


@rule("vec.length_sq")
def _length_sq(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """d |v|^2 = 2 v. Smooth everywhere."""
    (g,) = adj
    (v,) = ctx.operands(op)
    return [ctx.mul(v, scale(ctx, g, 2.0))]


@rule("vec.length")
def _length(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """d |v| = v / |v|. The zero vector: 0."""
    (g,) = adj
    (v,) = ctx.operands(op)
    n = ctx.primal(op.results[0])
    slope = ctx.mul(v, ctx.div(g, n))
    return [ctx.select(ctx.cmp("eq", n, ctx.zeros(n.type)), ctx.zeros(v.type), slope)]


@rule("vec.normalize")
def _normalize(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """d (v/|v|) = (g - u (u.g)) / |v| with u = v/|v|. The zero vector: 0."""
    (g,) = adj
    (v,) = ctx.operands(op)
    u = ctx.primal(op.results[0])
    n = ctx.emit("vec.length", v)
    tangent = ctx.sub(g, ctx.mul(u, ctx.emit("vec.dot", u, g)))
    slope = ctx.div(tangent, n)
    return [ctx.select(ctx.cmp("eq", n, ctx.zeros(n.type)), ctx.zeros(v.type), slope)]


@rule("vec.matmul")
def _matmul(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """C = A B: A gets G B^T, B gets A^T G (vectors as rows/columns). Bilinear."""
    (g,) = adj
    a, b = ctx.operands(op)
    if isinstance(a.type, MatrixType) and isinstance(b.type, MatrixType):
        return [
            ctx.emit("vec.matmul", g, ctx.emit("vec.transpose", b)),
            ctx.emit("vec.matmul", ctx.emit("vec.transpose", a), g),
        ]
    if isinstance(a.type, MatrixType):  # y = A x
        return [ctx.emit("vec.outer", g, b), ctx.emit("vec.matmul", g, a)]
    # y = x A (x a row vector)
    return [ctx.emit("vec.matmul", b, g), ctx.emit("vec.outer", a, g)]


@rule("vec.transpose")
def _transpose(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """The adjoint transposed back. Linear."""
    (g,) = adj
    return [ctx.emit("vec.transpose", g)]


@rule("vec.outer")
def _outer(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """M = a b^T: a gets G b, b gets G^T a. Bilinear."""
    (g,) = adj
    a, b = ctx.operands(op)
    return [ctx.emit("vec.matmul", g, b), ctx.emit("vec.matmul", a, g)]


# --- structs ---------------------------------------------------------------


def _zero_struct(ctx: VjpContext, st: StructType, like: Value) -> Value:
    """A zero adjoint of struct type ``st``; fields with no zero (arrays) come from ``like``."""
    fields = []
    for name, ft in st.fields:
        if ft.is_value and not isinstance(ft, StructType):
            fields.append(ctx.zeros(ft))
        else:
            part = ctx.emit("struct.extract", like, field=name)
            fields.append(_zero_struct(ctx, ft, part) if isinstance(ft, StructType) else part)
    return ctx.emit_typed("struct.construct", fields, st)


@rule("struct.construct")
def _struct_construct(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """Each differentiable field operand gets that field of the adjoint. Linear."""
    (g,) = adj
    st = g.type
    return [
        ctx.emit("struct.extract", g, field=name) if is_differentiable(ft) else None
        for name, ft in st.fields
    ]


@rule("struct.extract")
def _struct_extract(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """The struct gets zeros with the field set to the adjoint. Linear."""
    (g,) = adj
    (s,) = ctx.operands(op)
    zero = _zero_struct(ctx, s.type, s)
    return [ctx.emit("struct.insert", zero, g, field=op.attrs["field"])]


@rule("struct.insert")
def _struct_insert(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    """The struct gets the adjoint with the field zeroed; the new value gets the field. Linear."""
    (g,) = adj
    _s, x = ctx.operands(op)
    name = op.attrs["field"]
    if is_differentiable(x.type):
        zero = _zero_struct(ctx, x.type, x) if isinstance(x.type, StructType) else ctx.zeros(x.type)
        return [
            ctx.emit("struct.insert", g, zero, field=name),
            ctx.emit("struct.extract", g, field=name),
        ]
    return [g, None]  # the replaced field was not differentiable: nothing to clear


@rule("kd.record")
def _record(ctx: VjpContext, op: Operation, adj: Adj) -> list[Value | None]:
    # A runtime object's record is read-only object data named by an integer id: the
    # adjoint of what is read from it stops here (no gradient into the object).
    return [None]
