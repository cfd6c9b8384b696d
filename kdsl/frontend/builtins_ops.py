"""Warp's operator-named builtins and small utilities: ``add``, ``sub``, ``div``,
``floordiv``, ``mod``, ``neg``, ``pos``, ``unot``, ``bit_and``, ``bit_or``,
``bit_xor``, ``lshift``, ``rshift``, ``invert``, ``div_approx``, ``reversed`` and
``breakpoint``.

Each operator builtin is its operator: ``add(a, b)`` lowers through the same
``binop`` as ``a + b`` (Warp's typing: weak literals, no implicit promotion,
integer rules of
``docs/semantics.md``), so the two spellings cannot disagree: as in Warp,
``add``/``sub`` take two values of one type, ``div`` also a vector or matrix and a
scalar. ``mul`` lives in
``builtins_core`` with the vector builtins.
"""

from __future__ import annotations

import builtins as py
from typing import Any

from kdsl.errors import KdslSyntaxError, KdslTypeError
from kdsl.frontend.builtins_base import BuiltinTable, Lower
from kdsl.frontend.builtins_math import map_scalar, require_float, require_numeric
from kdsl.frontend.values import describe, is_weak
from kdsl.ir import Value
from kdsl.ir.catalog import fold_literal
from kdsl.ir.types import F32, I32, ArrayType, MatrixType, ScalarType, VectorType, elem_type

TABLE = BuiltinTable(__name__)


def _operand(em, x: Any, name: str, node) -> Any:
    if not (isinstance(x, Value) or is_weak(x)):
        raise em.error(KdslTypeError, f"{name}() cannot take {describe(x)}", node)
    return x


def _require_int(em, x: Any, name: str, node) -> None:
    """A located error unless ``x`` is an integer (literal, scalar, vector or matrix)."""
    if is_weak(x):
        ok = isinstance(x, int) and not isinstance(x, bool)
        got = describe(x)
    else:
        ok = isinstance(x.type, ScalarType | VectorType | MatrixType) and elem_type(x.type).is_int
        got = str(x.type)
    if not ok:
        raise em.error(KdslTypeError, f"{name}() needs integers, not {got}", node)


def _binary(op: str, name: str, ints: bool = False, floats: bool = False) -> Lower:
    def lower(em, args, node):
        a, b = (_operand(em, x, name, node) for x in args)
        if ints:
            _require_int(em, a, name, node)
            _require_int(em, b, name, node)
        if floats:
            for x in (a, b):
                if not is_weak(x):
                    require_float(em, x, name, node)
            if is_weak(a) and is_weak(b):
                a, b = float(a), float(b)
        return em.binop(op, a, b, node)

    return lower


for _name, _op, _what in [
    ("add", "add", "``a + b``"), ("sub", "sub", "``a - b``"),
    ("div", "div", "``a / b`` (integers: truncated; division by zero gives 0)"),
    ("floordiv", "floordiv", "``a // b`` (floored)"),
    ("mod", "mod", "``a % b``: the remainder of truncated division (C's ``fmod`` for floats; "
     "the sign of ``a``)"),
]:  # fmt: skip
    TABLE.define(_name, (2, 2), f"{_what}, typed as the operator (operands of one type; "
                 "``div`` also takes a vector or matrix and a scalar).", "operators")(_binary(_op, _name))  # fmt: skip

for _name, _op, _what in [
    ("bit_and", "and", "``a & b``"), ("bit_or", "or", "``a | b``"), ("bit_xor", "xor", "``a ^ b``"),
    ("lshift", "shl", "``a << b`` (a count outside ``[0, bits)`` gives 0)"),
    ("rshift", "shr", "``a >> b`` (arithmetic for signed types)"),
]:  # fmt: skip
    TABLE.define(_name, (2, 2), f"{_what} of integers (or integer vectors, componentwise).",
                 "operators")(_binary(_op, _name, ints=True))  # fmt: skip

TABLE.define("div_approx", (2, 2), "``a / b`` of floats (Warp: an approximate GPU division). kdsl "
             "divides exactly on every backend, so results match ``div``.", "operators")(
    _binary("div", "div_approx", floats=True))  # fmt: skip


@TABLE.define("neg", (1, 1), "``-x``.", "operators")
def _neg(em, args, node):
    x = _operand(em, args[0], "neg", node)
    if is_weak(x):
        return fold_literal("arith.neg", x)
    return em.emit("arith.neg", require_numeric(em, x, "neg", node), node=node)


@TABLE.define("pos", (1, 1), "``+x``: ``x`` unchanged.", "operators")
def _pos(em, args, node):
    x = _operand(em, args[0], "pos", node)
    return x if is_weak(x) else require_numeric(em, x, "pos", node)


@TABLE.define("invert", (1, 1), "``~x``: bitwise complement of an integer (componentwise for "
              "vectors).", "operators")  # fmt: skip
def _invert(em, args, node):
    x = _operand(em, args[0], "invert", node)
    _require_int(em, x, "invert", node)
    v = em.value(x, node)
    return map_scalar(em, lambda c: em.emit("arith.bitnot", c, node=node), v, node)


@TABLE.define("unot", (1, 1), "``not x``: a bool, a number (true when zero) or an array (true "
              "when it has no elements).", "operators")  # fmt: skip
def _unot(em, args, node):
    x = _operand(em, args[0], "unot", node)
    if is_weak(x):
        return fold_literal("arith.not", x)
    if isinstance(x.type, ArrayType):
        size = em.emit("kd.array_shape", x, node=node, dim=0)
        for d in range(1, x.type.ndim):
            size = em.emit("arith.mul", size, em.emit("kd.array_shape", x, node=node, dim=d),
                           node=node)  # fmt: skip
        return em.emit("arith.cmp", size, em.zero(size.type, node), node=node, pred="eq")
    return em.emit("arith.not", em.to_bool(x, node), node=node)


@TABLE.define("reversed", (1, 1), "``for i in reversed(range(...))``: the range backwards, as "
              "Python's ``reversed``. Only a for loop's iterable.", "control")  # fmt: skip
def _reversed(em, args, node):
    raise em.error(KdslSyntaxError, "reversed() can only wrap range(...) as the iterable of a "
                   "for loop", node)  # fmt: skip


@TABLE.define("breakpoint", (0, 0), "Warp: a debugger breakpoint. kdsl compiles it to nothing on "
              "every backend (use ``print``/``printf`` or the ``interp`` backend to debug).",
              "utility")  # fmt: skip
def _breakpoint(em, args, node):
    return None


# Python's own ``reversed`` and ``breakpoint`` mean these builtins in kernels.
TABLE.alias(py.reversed, "reversed")
TABLE.alias(py.breakpoint, "breakpoint")


def _scalar_dtype(em, dtype: Any, name: str, node) -> ScalarType:
    t = {py.float: F32, py.int: I32}.get(dtype) if _is_type(dtype) else None
    t = t or getattr(dtype, "__kdsl_type__", None)
    if not isinstance(t, ScalarType):
        raise em.error(KdslTypeError, f"{name}() needs a scalar type such as wp.int32, not "
                       f"{describe(dtype)}", node)  # fmt: skip
    return t


def _is_type(x: Any) -> bool:
    return isinstance(x, type)


@TABLE.define("cast", (2, 2), "``cast(a, dtype)``: the bits of scalar ``a`` reinterpreted as "
              "``dtype``, a numeric scalar type of the same width (``cast(int32(0x40000000), "
              "float32)`` is 2.0). Not differentiable.", "utility")  # fmt: skip
def _cast(em, args, node):
    x, dtype = args
    t = _scalar_dtype(em, dtype, "cast", node)
    if is_weak(x) and not isinstance(x, bool):
        # A literal takes the integer or float type of the target's width.
        if isinstance(x, float):
            kind = "float" if t.bits in (16, 32, 64) else None
        else:
            kind = "uint" if t.kind == "uint" else "int"
        x = em.value(x, node, want=ScalarType(kind, t.bits) if kind else F32)
    v = em.value(x, node)
    if not isinstance(v.type, ScalarType) or v.type.is_bool or t.is_bool:
        raise em.error(KdslTypeError, f"cast() reinterprets numeric scalars, not {v.type} as {t}",
                       node)  # fmt: skip
    if v.type.bits != t.bits:
        raise em.error(KdslTypeError, f"cast() needs types of one width: a {v.type} has "
                       f"{v.type.bits} bits, a {t} {t.bits}", node)  # fmt: skip
    if v.type == t:
        return v
    return em.emit_typed("arith.bitcast", [v], t, node)


@TABLE.define("block_dim", (0, 0), "Number of threads in the running block: 256 on cuda (the "
              "block size kdsl launches with), 1 on cpu and interp (as Warp on the CPU).", "utility")  # fmt: skip
def _block_dim(em, args, node):
    return em.emit("kd.block_dim", node=node)


@TABLE.define("thread_fence", (0, 0), "A memory fence across the launch (kdsl's, CUDA's "
              "``__threadfence``): this thread's memory reads and writes before it are ordered "
              "before those after it for every thread. Write, fence, then an atomic publishes "
              "the writes to a thread that sees the atomic's result and then fences.",
              "utility")  # fmt: skip
def _thread_fence(em, args, node):
    em.b.create("kd.fence", [], [], None, loc=em.loc(node))
