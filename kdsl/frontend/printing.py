"""``print(...)`` and ``wp.printf(fmt, ...)`` in kernels: both become one ``kd.print`` op.

``printf``'s format must be a string known at compile time (a literal or a captured
constant); each conversion is checked against its argument's type here, so a
mismatch is a located ``KdslTypeError`` instead of garbage at run time, and each
argument is cast to the type its conversion takes in the IR (``kdsl.ir.ops_print``).
Length modifiers (``%lld``) are accepted and ignored: the argument's type decides.

``print(a, b, sep=" ", end="\\n")`` prints like Python's ``print`` joined with Warp's
formats for values: floats ``%g``, integers in decimal, bools ``True``/``False``,
vectors ``"1 2 3 "``, quaternions ``"0 0 0 1"``, transforms ``"(1 2 3) (0 0 0 1)"``
and matrices one row per line, so ``print(v)`` writes what Warp's ``print(v)`` does.
Strings (literals, constants, f-string text) are copied into the format with every
``%`` doubled; backends escape the format for their target (it never reaches
generated code as raw text).
"""

from __future__ import annotations

import ast
import builtins as py
import re
from typing import Any

from kdsl.errors import KdslSyntaxError, KdslTypeError
from kdsl.frontend.builtins_base import Builtin, BuiltinTable, cast, unified
from kdsl.frontend.builtins_math import components
from kdsl.frontend.values import describe, is_weak
from kdsl.ir import Value
from kdsl.ir.ops_print import Conversion, FormatError, parse_format
from kdsl.ir.types import (
    BOOL,
    F64,
    I32,
    I64,
    U64,
    MatrixType,
    QuatType,
    ScalarType,
    TransformType,
    Type,
    VectorType,
    elem_type,
)


class AstBuiltin(Builtin):
    """A builtin whose ``lower`` receives the call's argument ASTs, not their values.

    ``print``/``printf`` need string literals, which are not values in kernels.
    ``lower(em, arg_nodes, node, **keyword_nodes)``.
    """

    def lower_nodes(self, em, node: ast.Call) -> Any:
        """Lower the call ``node`` (the expression visitor calls this instead of ``lower``)."""
        lo, hi = self.arity
        if not lo <= len(node.args) <= hi:
            raise em.error(KdslTypeError, f"{self.name}() takes {lo} to {hi} arguments, got "
                           f"{len(node.args)}", node)  # fmt: skip
        return self.lower(em, list(node.args), node, **{k.arg: k.value for k in node.keywords})


def _string(em, node: ast.expr, what: str) -> str:
    """A compile-time string: a literal or a name bound to a Python ``str``."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    if isinstance(node, ast.Name | ast.Attribute):
        v = em.visit(node)
        if isinstance(v, str):
            return v
        raise em.error(KdslTypeError, f"{what} must be a string constant, not {describe(v)}", node)
    raise em.error(KdslTypeError, f"{what} must be a string known at compile time", node)


def _is_string(em, node: ast.expr) -> bool:
    if isinstance(node, ast.Constant):
        return isinstance(node.value, str)
    if isinstance(node, ast.Name) and em.lookup_local(node.id, node) is None:
        return isinstance(em.globals.get(node.id), str)
    return False


# -- printf --------------------------------------------------------------------------


def _unsigned_of(t: ScalarType) -> ScalarType:
    return ScalarType("uint", t.bits)


def _convert(em, c: Conversion, x: Any, node: ast.expr) -> tuple[str, Value]:
    """Check one argument against its conversion; gives (IR conversion, IR operand)."""
    spelled = c.text(length=c.length)
    if is_weak(x):  # a literal: a float for float conversions, else its own type (C-like)
        if c.conv in "fFeEgG" and not isinstance(x, bool):
            x = em.const(float(x), F64, node)
        else:
            x = em.value(x, node)
    if not isinstance(x, Value) or not isinstance(x.type, ScalarType):
        got = x.type if isinstance(x, Value) else describe(x)
        raise em.error(KdslTypeError, f"'{spelled}' cannot format a {got}: printf takes scalars "
                       "(print() formats vectors and matrices)", node)  # fmt: skip
    t: ScalarType = x.type
    conv = c.conv
    if conv in "fFeEgG":
        if not t.is_float:
            raise em.error(KdslTypeError, f"'{spelled}' needs a float, got a {t} (convert it "
                           "with float(x), or use %d)", node)  # fmt: skip
        return conv, cast(em, F64, [x], node)
    if conv == "s":
        if t != BOOL:
            raise em.error(KdslTypeError, f"'{spelled}' prints a bool (kdsl has no strings), "
                           f"got a {t}", node)  # fmt: skip
        return conv, x
    if t.is_float:
        raise em.error(KdslTypeError, f"'{spelled}' needs an integer, got a {t} (use %f/%g, or "
                       "convert it with int(x))", node)  # fmt: skip
    if conv == "c":
        return conv, cast(em, I32, [x], node)
    if conv in "di":
        if t.kind == "uint" and t.bits == 64:
            return "u", x  # i64 cannot hold every u64: print it unsigned
        return conv, cast(em, I64, [x], node)
    # u o x X: the bits of the value's own width, as C prints them.
    if t.kind == "int":
        x = cast(em, _unsigned_of(t), [x], node)
    return conv, cast(em, U64, [x], node)


def _printf(em, arg_nodes: list[ast.expr], node: ast.Call) -> None:
    fmt = _string(em, arg_nodes[0], "printf's format")
    try:
        pieces = parse_format(fmt)
    except FormatError as e:
        raise em.error(KdslTypeError, f"printf: {e} (at offset {e.pos} of {fmt!r})",
                       arg_nodes[0]) from None  # fmt: skip
    convs = [p for p in pieces if isinstance(p, Conversion)]
    values = arg_nodes[1:]
    if len(convs) != len(values):
        raise em.error(KdslTypeError, f"printf: the format {fmt!r} has {len(convs)} conversions "
                       f"but {len(values)} arguments were given", node)  # fmt: skip
    out_fmt: list[str] = []
    operands: list[Value] = []
    for p in pieces:
        if isinstance(p, str):
            out_fmt.append(p.replace("%", "%%"))
            continue
        vnode = values[len(operands)]
        if _is_string(em, vnode):
            raise em.error(KdslTypeError, "printf: kdsl has no string values; put the text in "
                           "the format", vnode)  # fmt: skip
        conv, v = _convert(em, p, em.visit(vnode), vnode)
        out_fmt.append(p.text(conv))
        operands.append(v)
    _emit_print(em, "".join(out_fmt), operands, node)


# -- print ---------------------------------------------------------------------------


class _Format:
    """An IR format and its operands, built piece by piece."""

    def __init__(self) -> None:
        self.parts: list[str] = []
        self.operands: list[Value] = []

    def text(self, s: str) -> None:
        self.parts.append(s.replace("%", "%%"))

    def value(self, conv: str, v: Value) -> None:
        self.parts.append(conv)
        self.operands.append(v)


def _scalar_conv(em, f: _Format, v: Value, node, spec: str = "") -> None:
    """One scalar in print()'s style (or with a format spec's C conversion)."""
    t: ScalarType = v.type
    if t == BOOL:
        f.value(f"%{spec}s", v)
    elif t.is_float:
        f.value(f"%{spec or 'g'}", cast(em, F64, [v], node))
    elif t.kind == "uint":
        f.value(f"%{spec or 'u'}", cast(em, U64, [v], node))
    else:
        f.value(f"%{spec or 'd'}", cast(em, I64, [v], node))


def _extract(em, v: Value, node, *index: int) -> Value:
    return em.emit("vec.extract", v, *[em.const(i, I32, node) for i in index], node=node)


def _append_value(em, f: _Format, v: Value, node) -> None:
    t: Type = v.type
    if isinstance(t, ScalarType):
        _scalar_conv(em, f, v, node)
    elif isinstance(t, TransformType):
        for k in range(7):
            f.text("(" if k == 0 else ") (" if k == 3 else " ")
            _scalar_conv(em, f, _extract(em, v, node, k), node)
        f.text(")")
    elif isinstance(t, QuatType):
        for k in range(4):
            f.text(" " if k else "")
            _scalar_conv(em, f, _extract(em, v, node, k), node)
    elif isinstance(t, VectorType):
        for k in range(t.length):
            _scalar_conv(em, f, _extract(em, v, node, k), node)
            f.text(" ")
    elif isinstance(t, MatrixType):
        for r in range(t.rows):
            f.text("\n" if r else "")
            for c in range(t.cols):
                _scalar_conv(em, f, _extract(em, v, node, r, c), node)
                f.text(" ")
    else:
        raise em.error(KdslTypeError, f"print() cannot format a {t}", node)


#: A Python format spec kdsl can turn into a C conversion: [<][sign][#][0][width][.prec][type].
_SPEC = re.compile(r"(<)?([-+ ])?(#)?(0)?(\d+)?(?:\.(\d+))?([dfFeEgGxXo]?)")


def _spec_to_c(em, spec: str, t: ScalarType, node) -> str:
    """A Python format spec (``.3f``, ``>8``...) as C flags/width/precision/conversion."""
    m = _SPEC.fullmatch(spec)
    if m is None:
        raise em.error(KdslTypeError, f"unsupported format spec {spec!r} in a kernel f-string "
                       "(use [<][+- ][#][0][width][.precision][dfeEgGxXo])", node)  # fmt: skip
    left, sign, alt, zero, width, prec, conv = m.groups()
    flags = (
        ("-" if left else "") + (sign if sign in ("+", " ") else "") + (alt or "") + (zero or "")
    )
    if conv in ("d", "x", "X", "o") and t.is_float:
        raise em.error(KdslTypeError, f"format spec {spec!r} needs an integer, got a {t}", node)
    if conv and conv in "fFeEgG" and not t.is_float:
        raise em.error(KdslTypeError, f"format spec {spec!r} needs a float, got a {t}", node)
    if conv == "o" and alt:
        raise em.error(KdslTypeError, "the '#' flag of 'o' is not supported", node)
    body = flags + (width or "") + (f".{prec}" if prec is not None else "")
    if not conv:
        conv = "s" if t == BOOL else "g" if t.is_float else "u" if t.kind == "uint" else "d"
    return body + conv


def _append_fstring(em, f: _Format, node: ast.JoinedStr) -> None:
    for part in node.values:
        if isinstance(part, ast.Constant):
            f.text(str(part.value))
            continue
        assert isinstance(part, ast.FormattedValue)
        if part.conversion != -1:
            raise em.error(KdslSyntaxError, "!r, !s and !a are not supported in kernel f-strings",
                           part)  # fmt: skip
        x = em.visit(part.value)
        spec = ""
        if part.format_spec is not None:
            spec_parts = part.format_spec.values
            if not all(isinstance(s, ast.Constant) for s in spec_parts):
                raise em.error(KdslSyntaxError, "a kernel f-string's format spec must be constant",
                               part)  # fmt: skip
            spec = "".join(str(s.value) for s in spec_parts)
        if is_weak(x) and not spec:
            f.text(str(x))
            continue
        v = em.value(x, part.value)
        if spec:
            if not isinstance(v.type, ScalarType):
                raise em.error(KdslTypeError, f"a format spec needs a scalar, got a {v.type}",
                               part.value)  # fmt: skip
            c = _spec_to_c(em, spec, v.type, part.value)
            _convert_spec(em, f, c, v, part.value)
        else:
            _append_value(em, f, v, part.value)


def _convert_spec(em, f: _Format, c_spec: str, v: Value, node) -> None:
    pieces = parse_format("%" + c_spec)
    (c,) = pieces
    assert isinstance(c, Conversion)
    out_conv, operand = _convert(em, c, v, node)
    f.value(c.text(out_conv), operand)


def _print(em, arg_nodes: list[ast.expr], node: ast.Call, sep=None, end=None) -> None:
    sep_s = " " if sep is None else _string(em, sep, "print's sep")
    end_s = "\n" if end is None else _string(em, end, "print's end")
    f = _Format()
    for k, a in enumerate(arg_nodes):
        if k:
            f.text(sep_s)
        if _is_string(em, a):
            f.text(_string(em, a, "a string"))
        elif isinstance(a, ast.JoinedStr):
            _append_fstring(em, f, a)
        else:
            x = em.visit(a)
            if is_weak(x) or isinstance(x, str):
                f.text(str(x))  # a Python constant prints as Python prints it
            elif isinstance(x, Value):
                _append_value(em, f, x, a)
            else:
                raise em.error(KdslTypeError, f"print() cannot format {describe(x)}", a)
    f.text(end_s)
    _emit_print(em, "".join(f.parts), f.operands, node)


def _emit_print(em, fmt: str, operands: list[Value], node: ast.AST) -> None:
    em.b.create("kd.print", operands, [], {"format": fmt}, loc=em.loc(node))


TABLE = BuiltinTable(__name__)
#: ``print`` is reached through Python's own ``print`` only (no ``kdsl.print``, which a
#: star import would let shadow Python's).
PRINT = AstBuiltin(
    "print", _print,
    "``print(*values, sep=' ', end='\\n')``: write values like Python's print, with Warp's "
    "formats for floats (%g), vectors, matrices, quaternions and transforms.",
    (0, 64), "utility", keywords=("sep", "end"),
)  # fmt: skip
TABLE.alias(py.print, PRINT)
TABLE.add(AstBuiltin(
    "printf", _printf,
    "``printf(fmt, *args)``: C-style formatted output; ``fmt`` is a compile-time string "
    "checked against the argument types.",
    (1, 64), "utility",
))  # fmt: skip


# -- expect_eq / expect_neq / expect_near ------------------------------------------


def _expected_pair(em, args: list[Any], name: str, node) -> tuple[Value, Value]:
    a, b = unified(em, args[:2], node)
    if a.type != b.type:
        raise em.error(KdslTypeError, f"{name}() needs two values of one type, got {a.type} and "
                       f"{b.type}", node)  # fmt: skip
    return a, b


def _report(em, cond: Value, head: str, rows: list[tuple[str, Value]], node,
            head_value: Value | None = None) -> None:  # fmt: skip
    """``if cond:`` print ``head`` (then ``head_value``) and one ``label value`` line per
    row: the layout of Warp's messages."""

    def then() -> None:
        f = _Format()
        f.text(head)
        if head_value is not None:
            _append_value(em, f, head_value, node)
        f.text("\n")
        for label, v in rows:
            f.text(label)
            _append_value(em, f, v, node)
            f.text("\n")
        _emit_print(em, "".join(f.parts), f.operands, node)

    em.emit_if(cond, then, None, node)


def _expect(name: str, pred: str):
    def lower(em, args, node):
        a, b = _expected_pair(em, args, name, node)
        if not isinstance(a.type, ScalarType | VectorType | MatrixType | QuatType | TransformType):
            raise em.error(KdslTypeError, f"{name}() cannot compare a {a.type}", node)
        failed = em.emit("arith.cmp", a, b, node=node, pred=pred)
        _report(em, failed, f"Error, {name}() failed:", [("\t Expected: ", b), ("\t Actual: ", a)],
                node)  # fmt: skip
        return None

    return lower


TABLE.define("expect_eq", (2, 2), "``expect_eq(actual, expected)``: print an error (the expected "
             "and actual values) when they differ; the kernel goes on.", "utility")(
    _expect("expect_eq", "ne"))  # fmt: skip
TABLE.define("expect_neq", (2, 2), "``expect_neq(actual, expected)``: print an error when they "
             "are equal; the kernel goes on.", "utility")(_expect("expect_neq", "eq"))  # fmt: skip


@TABLE.define("expect_near", (2, 3), "``expect_near(actual, expected, tolerance=1e-6)``: print an "
              "error when a float (or a component of a vector, matrix or quaternion) differs by "
              "more than ``tolerance``; the kernel goes on.", "utility")  # fmt: skip
def _expect_near(em, args, node):
    a, b = _expected_pair(em, args, "expect_near", node)
    t = a.type
    if not (
        isinstance(t, ScalarType | VectorType | MatrixType | QuatType) and elem_type(t).is_float
    ):
        raise em.error(KdslTypeError, f"expect_near() needs floats, vectors, matrices or "
                       f"quaternions of floats, not {t}", node)  # fmt: skip
    et = elem_type(t)
    tol = em.value(args[2] if len(args) > 2 else 1.0e-6, node, want=et)
    if tol.type != et:
        raise em.error(KdslTypeError, f"expect_near(): the tolerance must be a {et}, not "
                       f"{tol.type}", node)  # fmt: skip
    diffs = components(em, em.emit("math.abs", em.emit("arith.sub", a, b, node=node), node=node),
                       node)  # fmt: skip
    diff = diffs[0]
    for d in diffs[1:]:
        diff = em.emit("arith.max", diff, d, node=node)
    failed = em.emit("arith.cmp", diff, tol, node=node, pred="gt")
    label = (
        "    Absolute difference: "
        if isinstance(t, ScalarType)
        else "    Max absolute difference: "
    )
    rows = [("    Expected: ", b), ("    Actual: ", a), (label, diff)]
    _report(em, failed, "Error, expect_near() failed with tolerance ", rows, node, tol)
    return None
