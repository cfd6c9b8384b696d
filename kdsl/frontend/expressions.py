"""Lowering of expressions: names, literals, operators, indexing, attributes, calls."""

from __future__ import annotations

import ast
import builtins as pybuiltins
from types import ModuleType
from typing import Any

import numpy as np

from kdsl.errors import (
    KdslAttributeError,
    KdslError,
    KdslIndexError,
    KdslNameError,
    KdslSyntaxError,
    KdslTypeError,
)
from kdsl.frontend import geometry, structs
from kdsl.frontend.builtins import PYTHON_ALIASES, PYTHON_CASTS
from kdsl.frontend.builtins_base import Builtin, cast
from kdsl.frontend.comparisons import comparison_type
from kdsl.frontend.emitter import Emitter, component_count
from kdsl.frontend.static import static
from kdsl.frontend.structs import is_indexed
from kdsl.frontend.values import ShapeOf, describe, is_hashable, is_weak
from kdsl.ir import Value
from kdsl.ir.catalog import fold_literal
from kdsl.ir.rewrite import constant_of
from kdsl.ir.types import (
    BOOL,
    I32,
    ArrayType,
    MatrixType,
    ScalarType,
    StructType,
    Type,
    VectorType,
)

#: Python's binary operators (``ast`` node types) -> the operator names ``binop`` takes;
#: also the augmented assignments' (``x += y``) in ``statements.py``.
BINOPS = {
    ast.Add: "add", ast.Sub: "sub", ast.Mult: "mul", ast.Div: "div", ast.FloorDiv: "floordiv",
    ast.Mod: "mod", ast.Pow: "pow", ast.BitAnd: "and", ast.BitOr: "or", ast.BitXor: "xor",
    ast.LShift: "shl", ast.RShift: "shr", ast.MatMult: "matmul",
}  # fmt: skip
_CMPOPS = {ast.Eq: "eq", ast.NotEq: "ne", ast.Lt: "lt", ast.LtE: "le", ast.Gt: "gt", ast.GtE: "ge"}
#: Vector component attributes (``v.x`` ... ``v.w``) -> their index, read here and
#: assigned in ``statements.py``.
COMPONENTS = {"x": 0, "y": 1, "z": 2, "w": 3}


class ExpressionLowering(Emitter):
    """Expression visitors. Each returns a frontend value (see ``values.py``)."""

    globals: dict[str, Any]

    # --- names and constants ------------------------------------------------------

    def visit_Constant(self, node: ast.Constant) -> Any:
        if isinstance(node.value, bool | int | float):
            return node.value
        if isinstance(node.value, str):
            raise self.error(KdslSyntaxError, "strings are not supported in kernels", node)
        raise self.error(KdslSyntaxError, f"unsupported constant {node.value!r}", node)

    def visit_Name(self, node: ast.Name) -> Any:
        v = self.lookup_local(node.id, node)
        if v is not None:
            return v
        if node.id in self.globals:
            return self.python_value(self.globals[node.id], node)
        if hasattr(pybuiltins, node.id):
            return getattr(pybuiltins, node.id)
        raise self.error(KdslNameError, f"name '{node.id}' is not defined", node)

    def visit_Attribute(self, node: ast.Attribute) -> Any:
        base = self.visit(node.value)
        if isinstance(base, Value):
            return self.value_attribute(base, node.attr, node)
        if isinstance(base, ModuleType | type) or not is_weak(base):
            try:
                obj = getattr(base, node.attr)
            except AttributeError:
                raise self.error(
                    KdslNameError, f"{describe(base)} has no attribute '{node.attr}'", node
                ) from None
            return self.python_value(obj, node)
        raise self.error(
            KdslAttributeError, f"{describe(base)} has no attribute '{node.attr}'", node
        )

    def value_attribute(self, v: Value, attr: str, node: ast.AST) -> Any:
        t = v.type
        if isinstance(t, ArrayType) and attr == "shape":
            return ShapeOf(v)
        if geometry.has_part(t, attr):  # transform.p, transform.q
            return geometry.part(self, v, attr, node)
        if isinstance(t, VectorType) and attr in COMPONENTS:
            k = COMPONENTS[attr]
            if k >= t.length:
                raise self.error(KdslAttributeError, f"a {t} has no component '.{attr}'", node)
            return self.emit("vec.extract", v, self.const(k, I32, node), node=node)
        if is_indexed(t) and attr == "shape":
            return structs.indexed_shape(self, v, node)
        if isinstance(t, StructType):
            return self.emit("struct.extract", v, node=node, field=attr)
        raise self.error(KdslAttributeError, f"a {t} has no attribute '.{attr}'", node)

    def visit_Tuple(self, node: ast.Tuple) -> Any:
        return tuple(self.visit(e) for e in node.elts)

    # --- operators ----------------------------------------------------------------

    def visit_BinOp(self, node: ast.BinOp) -> Any:
        op = BINOPS.get(type(node.op))
        return self.binop(op, self.visit(node.left), self.visit(node.right), node)

    def binop(self, op: str, a: Any, b: Any, node: ast.AST) -> Any:
        """``a op b`` with Warp's typing (weak literals, no implicit promotion)."""
        for x in (a, b):
            if not (isinstance(x, Value) or is_weak(x)):
                raise self.error(KdslTypeError, f"cannot use {describe(x)} in arithmetic", node)
        if is_weak(a) and is_weak(b):
            # Two literals combine as Python combines them, where the op says so
            # (``2 * 3``); otherwise they take types and the op is emitted (``7 / 2``).
            folded = fold_literal(f"arith.{op}", a, b)
            if folded is not None:
                return folded
        x, y = self.coerce_pair(a, b, node)
        special = geometry.binop(self, op, x, y, node)  # q1 * q2, t1 * t2
        if special is not None:
            return special
        if op == "matmul" or (op == "mul" and _is_matmul(x.type, y.type)):
            return self.emit("vec.matmul", x, y, node=node)
        return self.emit(f"arith.{op}", x, y, node=node)

    def visit_UnaryOp(self, node: ast.UnaryOp) -> Any:
        x = self.visit(node.operand)
        if isinstance(node.op, ast.Not):
            if is_weak(x):
                return fold_literal("arith.not", x)
            truth = self.static_truth(x)
            if truth is not None:  # `not wp.static(c)` with a typed constant
                return not truth
            return self.emit("arith.not", self.to_bool(x, node.operand), node=node)
        if is_weak(x) and not isinstance(node.op, ast.Invert):
            return fold_literal("arith.neg", x) if isinstance(node.op, ast.USub) else x
        v = self.value(x, node)
        if isinstance(node.op, ast.UAdd):
            return v
        return self.emit("arith.neg" if isinstance(node.op, ast.USub) else "arith.bitnot", v,
                         node=node)  # fmt: skip

    def visit_BoolOp(self, node: ast.BoolOp) -> Any:
        # Short-circuit: the right operand runs inside an scf.if, so `i < n and a[i] > 0`
        # never reads a[i] out of bounds.
        is_and = isinstance(node.op, ast.And)
        result = self.visit(node.values[0])
        for rhs in node.values[1:]:
            truth = self.static_truth(result)
            if truth is not None:  # a compile-time operand: the other is lowered only if needed
                if truth != is_and:
                    return truth
                result = self.visit(rhs)
                continue
            cond = self.to_bool(result, node)

            def lhs_value(c=cond):
                return c

            def rhs_value(r=rhs):
                return self.to_bool(self.visit(r), r)

            then_fn, else_fn = (rhs_value, lambda: False) if is_and else (lambda: True, rhs_value)
            result = self.if_value(cond, then_fn, else_fn, node, BOOL)
        return result if not is_weak(result) else bool(result)

    def visit_Compare(self, node: ast.Compare) -> Any:
        left = self.visit(node.left)
        result: Any = None
        for op_node, right_node in zip(node.ops, node.comparators):
            pred = _CMPOPS.get(type(op_node))
            if pred is None:
                raise self.error(KdslSyntaxError, "'in'/'is' comparisons are not supported", node)
            right = self.visit(right_node)
            if is_weak(left) and is_weak(right):
                r: Any = fold_literal("arith.cmp", left, right, pred=pred)
            else:
                x, y = self.comparable_pair(left, right, node)
                r = self.emit("arith.cmp", x, y, node=node, pred=pred)
            if result is None:
                result = r
            elif is_weak(result) and is_weak(r):
                result = result and r
            else:
                result = self.emit("arith.and", self.to_bool(result, node), self.to_bool(r, node),
                                   node=node)  # fmt: skip
            left = right
        return result

    def comparable_pair(self, left: Any, right: Any, node: ast.AST) -> tuple[Value, Value]:
        """Two operands of a comparison, scalars of different types converted to a common
        one as Warp's C comparisons do (the rule is in ``comparisons.py``)."""
        x, y = self.coerce_pair(left, right, node)
        a, b = x.type, y.type
        if a == b or not (isinstance(a, ScalarType) and isinstance(b, ScalarType)):
            return x, y
        common = comparison_type(a, b)
        if isinstance(common, str):
            raise self.error(KdslTypeError, common, node)
        return cast(self, common, [x], node), cast(self, common, [y], node)

    def visit_IfExp(self, node: ast.IfExp) -> Any:
        cond = self.visit(node.test)
        truth = self.static_truth(cond)
        if truth is not None:  # the arm not taken is never lowered (nor type-checked)
            return self.visit(node.body if truth else node.orelse)
        c = self.to_bool(cond, node.test)
        # Both arms are typed together; a literal arm takes the other arm's type.
        return self.if_value(c, lambda: self.visit(node.body), lambda: self.visit(node.orelse),
                             node, None)  # fmt: skip

    def static_truth(self, cond: Any) -> bool | None:
        """The truth of a condition known at compile time, else None.

        A literal, a ``static(...)`` result or closure constant, and a typed scalar
        constant (``np.bool_(True)``, ``wp.static(wp.float64(x) > 0)``) are known: as in
        Warp, ``if``/``elif``, conditional expressions, ``and``/``or`` and ``not`` then
        lower only the side taken, and the other is never type-checked.
        """
        if is_weak(cond):
            return bool(cond)
        if isinstance(cond, Value) and isinstance(cond.type, ScalarType):
            known, c = constant_of(cond)
            if known:
                return bool(c)
        return None

    # --- indexing -----------------------------------------------------------------

    def index_list(self, node: ast.expr) -> list[Any]:
        if isinstance(node, ast.Tuple):
            return [self.visit(e) for e in node.elts]
        if isinstance(node, ast.Slice):
            raise self.error(KdslSyntaxError, "slices are not supported in kernels", node)
        return [self.visit(node)]

    def indices(self, base: Value, idx: list[Any], node: ast.AST) -> list[Value]:
        """Index values as i32 (negative constant indices count from a vector's end)."""
        out = []
        shape = getattr(base.type, "shape", None)
        for k, i in enumerate(idx):
            if is_weak(i) and not isinstance(i, bool) and isinstance(i, int):
                if i < 0 and shape is not None and k < len(shape):
                    i += shape[k]
                out.append(self.const(i, I32, node))
                continue
            v = self.value(i, node)
            if not (isinstance(v.type, ScalarType) and v.type.is_int):
                raise self.error(KdslTypeError, f"an index must be an integer, not {v.type}", node)
            out.append(v)
        return out

    def visit_Subscript(self, node: ast.Subscript) -> Any:
        base = self.visit(node.value)
        idx = self.index_list(node.slice)
        if isinstance(base, ShapeOf):
            if len(idx) != 1 or not isinstance(idx[0], int):
                raise self.error(KdslTypeError, "shape[...] needs one constant index", node)
            return self.emit("kd.array_shape", base.array, node=node, dim=idx[0])
        if isinstance(base, tuple):
            if len(idx) == 1 and isinstance(idx[0], int) and -len(base) <= idx[0] < len(base):
                return base[idx[0]]
            raise self.error(KdslIndexError, "a tuple needs one constant index in range", node)
        if not isinstance(base, Value):
            raise self.error(KdslTypeError, f"cannot index {describe(base)}", node)
        return self.load_element(base, idx, node)

    def load_element(self, base: Value, idx: list[Any], node: ast.AST) -> Value:
        t = base.type
        if isinstance(t, ArrayType):
            if len(idx) > t.ndim:
                raise self.error(
                    KdslTypeError,
                    f"too many indices for a {t.ndim}-d array: got {len(idx)}, expected {t.ndim}",
                    node,
                )
            op = "kd.load" if len(idx) == t.ndim else "kd.array_view"  # a[i]: a row, as Warp's
            return self.emit(op, base, *self.indices(base, idx, node), node=node)
        if isinstance(t, VectorType | MatrixType):
            return self.emit("vec.extract", base, *self.indices(base, idx, node), node=node)
        if is_indexed(t):
            data, ix = structs.indexed_element(self, base, idx, node)
            return self.emit("kd.load", data, *ix, node=node)
        raise self.error(KdslTypeError, f"a value of type {t} cannot be indexed", node)

    # --- calls --------------------------------------------------------------------

    def visit_Call(self, node: ast.Call) -> Any:
        fn = self.visit(node.func)
        if fn is static:
            return self.eval_static(node)
        if any(isinstance(a, ast.Starred) for a in node.args):
            raise self.error(KdslSyntaxError, "starred arguments (*args) are not supported", node)
        # Keyword arguments go only to builtins that name them (``identity(n=3, dtype=float)``).
        target = PYTHON_ALIASES.get(fn, fn) if is_hashable(fn) else fn
        allowed = (
            target.keywords
            if isinstance(target, Builtin)
            else getattr(target, "__kdsl_keywords__", ())
        )  # struct fields
        for kw in node.keywords:
            if kw.arg is not None and hasattr(target, "__kdsl_overloads__"):
                continue  # a @kdsl.func binds keywords to its parameters (pick_overload)
            if kw.arg is None or kw.arg not in allowed:
                what = f"'{kw.arg}'" if kw.arg else "**kwargs"
                takes = f"only {', '.join(allowed)} as" if allowed else "no"
                raise self.error(KdslTypeError, f"{_callee_name(fn)}() takes {takes} keyword "
                                 f"arguments (got {what})", node)  # fmt: skip
        lower_nodes = getattr(target, "lower_nodes", None)
        if lower_nodes is not None:  # print/printf read string literals from the AST
            return lower_nodes(self, node)
        kwargs = {kw.arg: self.visit(kw.value) for kw in node.keywords}
        args = [self.visit(a) for a in node.args]
        return self.call(fn, args, node, kwargs)

    def call(self, fn: Any, args: list[Any], node: ast.Call, kwargs: dict | None = None) -> Any:
        fn = PYTHON_ALIASES.get(fn, fn) if is_hashable(fn) else fn
        if isinstance(fn, Builtin):
            lo, hi = fn.arity
            if not lo <= len(args) <= hi:
                want = str(lo) if lo == hi else f"{lo} to {hi}"
                raise self.error(
                    KdslTypeError,
                    f"{fn.name}() takes {want} arguments, got {len(args)}",
                    node,
                )
            return fn.lower(self, args, node, **kwargs) if kwargs else fn.lower(self, args, node)
        if is_hashable(fn) and fn in PYTHON_CASTS:
            self.check_cast_args(fn.__name__, args, node)
            return cast(self, PYTHON_CASTS[fn], args, node)
        t = getattr(fn, "__kdsl_type__", None) if isinstance(fn, type) else None
        if isinstance(t, ScalarType):
            self.check_cast_args(fn.__name__, args, node)
            return cast(self, t, args, node)
        if isinstance(t, VectorType | MatrixType):
            return self.construct(t, args, node)
        if isinstance(t, StructType):
            return structs.construct(self, t, args, kwargs or {}, node)
        if hasattr(fn, "__kdsl_overloads__"):
            return self.call_user(fn, args, node, kwargs)
        if fn is range:
            raise self.error(
                KdslSyntaxError, "range() can only be the iterable of a for loop", node
            )
        if getattr(fn, "__kdsl_kernel__", False):
            raise self.error(KdslSyntaxError, "a kernel cannot call another kernel", node)
        lower_call = getattr(fn, "lower_call", None)  # kdsl.grad and what it returns
        if lower_call is not None:
            return lower_call(self, args, node, kwargs or {})
        raise self.error(KdslTypeError, f"{describe(fn)} cannot be called in a kernel", node)

    def check_cast_args(self, name: str, args: list[Any], node: ast.AST) -> None:
        if len(args) > 1:
            raise self.error(KdslTypeError, f"{name}() takes 0 or 1 arguments, got {len(args)}",
                             node)  # fmt: skip

    def construct(self, t: Type, args: list[Any], node: ast.AST) -> Value:
        """``vec3(...)``/``mat33(...)``: zeros, a splat, a cast, or components/rows."""
        if not args:
            return self.zero(t, node)
        if len(args) == 1:
            x = args[0]
            if is_weak(x) or (isinstance(x, Value) and isinstance(x.type, ScalarType)):
                return self.emit_typed("vec.splat", [self.value(x, node, want=t.elem)], t, node)
            v = self.value(x, node)
            if v.type == t:
                return v
            if getattr(v.type, "shape", None) == t.shape:
                return self.emit_typed("arith.cast", [v], t, node)
        parts = []
        for x in args:
            v = self.value(x, node, want=t.elem)
            if isinstance(v.type, ScalarType | VectorType) and v.type != t.elem and (
                getattr(v.type, "elem", v.type) != t.elem):  # fmt: skip
                raise self.error(
                    KdslTypeError, f"cannot build a {t} from a {v.type}: components must be "
                    f"{t.elem}; cast them first", node)  # fmt: skip
            parts.append(v)
        total = sum(component_count(v.type) for v in parts)
        if total != component_count(t):
            raise self.error(
                KdslTypeError,
                f"{t} takes {component_count(t)} components, but {total} were given",
                node,
            )
        return self.emit_typed("vec.construct", parts, t, node)

    def eval_static(self, node: ast.Call) -> Any:
        """``static(expr)``: evaluate ``expr`` in Python now; the result must be a constant."""
        if len(node.args) != 1 or node.keywords:
            raise self.error(KdslTypeError, "static() takes exactly one expression", node)
        expr = ast.Expression(node.args[0])
        try:
            code = compile(ast.fix_missing_locations(expr), self.src.file, "eval")
            result = eval(code, dict(self.globals))
        except KdslError:
            raise
        except Exception as e:  # the user's expression may raise anything
            raise self.error(
                KdslTypeError, f"static() expression failed: {type(e).__name__}: {e}", node
            ) from None
        if isinstance(result, range | tuple | list) and all(
            isinstance(v, int) and not isinstance(v, bool) for v in result
        ):
            return result  # only usable as the iterable of a for loop (unrolled)
        if hasattr(result, "__kdsl_overloads__") or isinstance(result, Builtin):
            return result  # a function picked at compile time, to be called
        ok = is_weak(result) or hasattr(result, "__kdsl_type__")
        ok = ok or (isinstance(result, np.generic) and result.dtype.kind in "biuf")
        if not ok:
            raise self.error(
                KdslTypeError,
                "static() must give a compile-time constant (a number, vector, type, range "
                f"or a @kdsl.func), got {describe(result)}",
                node,
            )
        return self.python_value(result, node)


def _is_matmul(a: Type, b: Type) -> bool:
    return (isinstance(a, MatrixType) and isinstance(b, MatrixType | VectorType)) or (
        isinstance(a, VectorType) and isinstance(b, MatrixType))  # fmt: skip


def _callee_name(fn: Any) -> str:
    return getattr(fn, "name", None) or getattr(fn, "__name__", None) or "this function"
