"""Lowering of statements: assignment, if/for/while, break/continue/return."""

from __future__ import annotations

import ast
from typing import Any

from kdsl.errors import KdslAttributeError, KdslNameError, KdslSyntaxError, KdslTypeError
from kdsl.frontend import geometry, structs
from kdsl.frontend.analysis import BREAK, CONTINUE, RETURN, always_exits, exits
from kdsl.frontend.builtins import BUILTINS, PYTHON_ALIASES
from kdsl.frontend.control import BRK, CONT, MAX_UNROLL, RET, ControlFlowLowering
from kdsl.frontend.expressions import BINOPS, COMPONENTS
from kdsl.frontend.library import query_iterator
from kdsl.frontend.static import static
from kdsl.frontend.structs import is_indexed
from kdsl.frontend.values import ShapeOf, describe, is_hashable
from kdsl.ir import Value
from kdsl.ir.types import BOOL, I32, ArrayType, MatrixType, StructType, VectorType


class StatementLowering(ControlFlowLowering):
    """Statement visitors. ``kind`` is "kernel" or "func"; ``loop_depth`` counts loops."""

    kind: str
    loop_depth: int = 0
    res_types: list | None = None
    tid_ndim: int | None = None

    def visit_body(self, stmts: list[ast.stmt]) -> None:
        for i, s in enumerate(stmts):
            rest = stmts[i + 1 :]
            if isinstance(s, ast.If) and not s.orelse and rest and always_exits(s.body):
                # `if c: return` + rest lowers as if/else: no flag guard needed.
                self.visit_If(s, else_body=rest)
                return
            self.visit(s)
            if isinstance(s, ast.Return | ast.Break | ast.Continue):
                return  # the rest is unreachable
            kinds = exits(s)
            if kinds and rest:
                guard = self.flag_guard(kinds, s)
                if guard is not None:
                    self.emit_if(guard, lambda r=rest: self.visit_body(r), None, rest[0])
                    return

    # --- simple statements ----------------------------------------------------------

    def visit_Pass(self, node: ast.Pass) -> None:
        pass

    def visit_Expr(self, node: ast.Expr) -> None:
        if isinstance(node.value, ast.Constant) and isinstance(node.value.value, str):
            return  # docstring
        self.visit(node.value)

    def visit_Assign(self, node: ast.Assign) -> None:
        value = self.rhs(node.value, node.targets)
        for target in node.targets:
            self.assign(target, value, node)

    def rhs(self, value: ast.expr, targets: list[ast.expr]) -> Any:
        # tid() takes its dimension count from the names it is unpacked into.
        call = isinstance(value, ast.Call) and not value.args and not value.keywords
        if call and self.visit(value.func) is BUILTINS["tid"]:
            t = targets[0]
            n = len(t.elts) if isinstance(t, ast.Tuple | ast.List) else 1
            return self.tid(n, value)
        return self.visit(value)

    def visit_AnnAssign(self, node: ast.AnnAssign) -> None:
        from kdsl.types import type_of

        if node.value is None:
            raise self.error(KdslSyntaxError, "a declaration needs a value", node)
        ann = self.visit(node.annotation)
        try:
            t = type_of(ann)
        except TypeError:
            raise self.error(KdslTypeError, f"{describe(ann)} is not a kdsl type", node) from None
        v = self.value(self.visit(node.value), node.value, want=t)
        if v.type != t:
            raise self.error(KdslTypeError, f"cannot assign a {v.type} to a {t} variable", node)
        self.assign(node.target, v, node)

    def visit_AugAssign(self, node: ast.AugAssign) -> None:
        if isinstance(node.op, ast.Add | ast.Sub) and self.atomic_update(node):
            return
        current = self.visit(node.target)
        op = BINOPS[type(node.op)]
        self.assign(node.target, self.binop(op, current, self.visit(node.value), node), node)

    def atomic_update(self, node: ast.AugAssign) -> bool:
        """``arr[i...] += x`` / ``-= x`` on an array element is an atomic add/sub, as in
        Warp (other operators, and components of elements, read and write back)."""
        target = node.target
        # Only a named array (or a struct's array field): evaluating the base twice
        # (here, then in the read-modify-write path) must have no effect.
        if not (isinstance(target, ast.Subscript) and _plain_base(target.value)):
            return False
        base = self.visit(target.value)
        if not (isinstance(base, Value) and isinstance(base.type, ArrayType)):
            return False
        idx = self.index_list(target.slice)
        if len(idx) != base.type.ndim:
            return False
        v = self.value(self.visit(node.value), node.value, want=base.type.dtype)
        kind = "add" if isinstance(node.op, ast.Add) else "sub"
        self.emit("kd.atomic_rmw", v, base, *self.indices(base, idx, target), node=node, kind=kind)
        return True

    def assign(self, target: ast.expr, value: Any, node: ast.AST) -> None:
        """Bind ``value`` to ``target``: a name, a tuple, an element or a component."""
        if isinstance(target, ast.Tuple | ast.List):
            if not isinstance(value, tuple):
                raise self.error(KdslTypeError, f"cannot unpack {describe(value)}", target)
            if len(value) != len(target.elts):
                raise self.error(
                    KdslTypeError,
                    f"cannot unpack {len(value)} values into {len(target.elts)} names",
                    target,
                )
            for t, v in zip(target.elts, value):
                self.assign(t, v, node)
        elif isinstance(target, ast.Name):
            self.assign_name(target.id, value, target)
        elif isinstance(target, ast.Subscript):
            self.assign_subscript(target, value)
        elif isinstance(target, ast.Attribute):
            self.assign_attribute(target, value)
        elif isinstance(target, ast.Starred):
            raise self.error(KdslSyntaxError, "starred assignment is not supported", target)
        else:
            raise self.error(KdslSyntaxError, "cannot assign to this expression", target)

    def assign_name(self, name: str, value: Any, node: ast.AST) -> None:
        if isinstance(value, tuple):
            raise self.error(
                KdslTypeError,
                f"cannot store a tuple of {len(value)} values in '{name}'; unpack it: a, b = ...",
                node,
            )
        old = self.vars.get(name)
        if old is not None and isinstance(old.type, ArrayType):
            raise self.error(KdslSyntaxError, f"cannot assign to the array '{name}'", node)
        v = self.value(value, node, want=old.type if old is not None else None)
        if old is None and isinstance(v.type, ArrayType):  # r = a[i]: a name for a view
            self.bind_raw(name, v)
            return
        if not v.type.is_value:
            raise self.error(KdslTypeError, f"cannot store a {v.type} in a variable", node)
        if old is not None and old.type != v.type:
            raise self.error(
                KdslTypeError,
                f"variable '{name}' changes type from {old.type} to {v.type}; a variable "
                "keeps the type of its first assignment (cast the value)",
                node,
            )
        self.bind_raw(name, v)

    def assign_subscript(self, target: ast.Subscript, value: Any) -> None:
        base = self.visit(target.value)
        idx = self.index_list(target.slice)
        if not isinstance(base, Value) or isinstance(base, ShapeOf):
            raise self.error(KdslTypeError, f"cannot assign into {describe(base)}", target)
        t = base.type
        if isinstance(t, ArrayType):
            if len(idx) != t.ndim:
                raise self.error(
                    KdslTypeError, f"a {t.ndim}-d array needs {t.ndim} indices, got {len(idx)}",
                    target)  # fmt: skip
            v = self.value(value, target, want=t.dtype)
            try:
                self.b.create("kd.store", [v, base, *self.indices(base, idx, target)],
                              loc=self.loc(target))  # fmt: skip
            except TypeError as e:
                raise self.error(KdslTypeError, str(e), target) from None
            return
        if is_indexed(t):  # an indexedarray: store through its index arrays
            data, ix = structs.indexed_element(self, base, idx, target)
            v = self.value(value, target, want=data.type.dtype)
            try:
                self.b.create("kd.store", [v, data, *ix], loc=self.loc(target))
            except TypeError as e:
                raise self.error(KdslTypeError, str(e), target) from None
            return
        if not isinstance(t, VectorType | MatrixType):
            raise self.error(KdslTypeError, f"a value of type {t} cannot be indexed", target)
        ix = self.indices(base, idx, target)
        want = t.elem if isinstance(t, VectorType) or len(ix) == 2 else t.row_type
        v = self.value(value, target, want=want)
        self.assign(target.value, self.emit("vec.insert", base, v, *ix, node=target), target)

    def assign_attribute(self, target: ast.Attribute, value: Any) -> None:
        base = self.visit(target.value)
        if not isinstance(base, Value):
            raise self.error(KdslSyntaxError, f"cannot assign to an attribute of {describe(base)}",
                             target)  # fmt: skip
        t = base.type
        if isinstance(t, VectorType) and target.attr in COMPONENTS:
            k = COMPONENTS[target.attr]
            if k >= t.length:
                raise self.error(KdslTypeError, f"a {t} has no component '.{target.attr}'", target)
            v = self.value(value, target, want=t.elem)
            new = self.emit("vec.insert", base, v, self.const(k, I32, target), node=target)
        elif geometry.has_part(t, target.attr):  # transform.p = v, transform.q = q
            new = geometry.with_part(self, base, target.attr, value, target)
        elif isinstance(t, StructType):
            v = self.value(value, target, want=t.field_type(target.attr))
            new = self.emit("struct.insert", base, v, node=target, field=target.attr)
        else:
            raise self.error(
                KdslAttributeError, f"a {t} has no attribute '.{target.attr}'", target
            )
        self.assign(target.value, new, target)

    # --- control flow ---------------------------------------------------------------

    def visit_If(self, node: ast.If, else_body: list[ast.stmt] | None = None) -> None:
        orelse = node.orelse if else_body is None else else_body
        cond = self.visit(node.test)
        truth = self.static_truth(cond)
        if truth is not None:  # a compile-time condition picks its branch now
            self.visit_body(node.body if truth else orelse)
            return
        c = self.to_bool(cond, node.test)
        self.emit_if(
            c, lambda: self.visit_body(node.body),
            (lambda: self.visit_body(orelse)) if orelse else None, node,
        )  # fmt: skip

    def visit_For(self, node: ast.For) -> None:
        if node.orelse:
            raise self.error(KdslSyntaxError, "for/else is not supported", node)
        if not isinstance(node.target, ast.Name):
            raise self.error(KdslSyntaxError, "a for loop needs one loop variable", node.target)
        it = node.iter
        static_iter = isinstance(it, ast.Call) and self.visit(it.func) is static
        if static_iter:
            values = self.visit(it)
            if not isinstance(values, range | tuple | list):
                raise self.error(KdslTypeError, "static() in a for loop must give a range", it)
            self.unroll(node, list(values))
            return
        if isinstance(it, ast.Name):  # for index in query: (a geometry query, as in Warp)
            q = self.lookup_local(it.id, it)
            advance = query_iterator(q.type) if isinstance(q, Value) else None
            if advance is not None:
                self.lower_query_for(node, it.id, advance)
                return
        backwards = _is_reversed_range(self, it)
        if backwards:  # for i in reversed(range(...))
            it = it.args[0]
        if not (isinstance(it, ast.Call) and self.visit(it.func) is range):
            raise self.error(KdslSyntaxError, "a for loop must iterate over range(...)", it)
        if it.keywords or not 1 <= len(it.args) <= 3:
            raise self.error(KdslTypeError, "range() takes 1 to 3 positional arguments", it)
        args = [self.visit(a) for a in it.args]
        unroll = any(isinstance(a, ast.Call) and self.visit(a.func) is static for a in it.args)
        if unroll:
            if not all(isinstance(a, int) and not isinstance(a, bool) for a in args):
                raise self.error(KdslTypeError, "static range bounds must be integers", it)
            values = list(range(*args))
            self.unroll(node, values[::-1] if backwards else values)
            return
        self.loop_depth += 1
        try:
            bounds = self.range_bounds(args, it)
            if backwards:
                bounds = self.reversed_bounds(bounds, it)
            self.lower_range_for(node.target.id, bounds, node.body, node)
        finally:
            self.loop_depth -= 1

    def lower_query_for(self, node: ast.For, query: str, advance: Any) -> None:
        """``for index in query: body`` as ``index = 0; while advance(query, index): body``
        (``advance`` updates both in place: the in-out call rebinding of ``inout.py``)."""
        name = f"__kdsl_query_next_{getattr(advance, '__name__', 'fn')}"
        self.globals[name] = advance
        target = node.target.id
        init = ast.Assign(targets=[ast.Name(id=target, ctx=ast.Store())], value=ast.Constant(0))
        test = ast.Call(
            func=ast.Name(id=name, ctx=ast.Load()),
            args=[ast.Name(id=query, ctx=ast.Load()), ast.Name(id=target, ctx=ast.Load())],
            keywords=[],
        )
        loop = ast.While(test=test, body=node.body, orelse=[])
        for new in (init, *ast.walk(init), loop, *ast.walk(test)):
            ast.copy_location(new, node)
        self.visit(init)
        self.visit(loop)

    def range_bounds(self, args: list[Any], node: ast.AST) -> list[Value]:
        lb, ub, step = (0, args[0], 1) if len(args) == 1 else (*args, 1)[:3]
        out = []
        for a in (lb, ub, step):
            v = self.value(a, node, want=I32)
            if not (v.type.is_scalar and v.type.is_int):
                raise self.error(KdslTypeError, f"range() bounds must be integers, not {v.type}",
                                 node)  # fmt: skip
            out.append(v)
        if len({v.type for v in out}) != 1:
            raise self.error(KdslTypeError, "range() bounds must have one integer type", node)
        if isinstance(step, int) and step == 0:
            raise self.error(KdslTypeError, "range() step must not be zero", node)
        return out

    def reversed_bounds(self, bounds: list[Value], node: ast.AST) -> list[Value]:
        """``reversed(range(lb, ub, step))`` as a range: ``(last, lb - step, -step)``, or
        an empty range when the range is empty (Warp's ``iter_reverse``)."""
        lb, ub, step = bounds
        t = lb.type
        zero, one = self.const(0, t, node), self.const(1, t, node)
        up = self.emit("arith.cmp", step, zero, node=node, pred="gt")
        sign = self.emit("arith.select", up, one, self.const(-1, t, node), node=node)
        nonempty = self.emit("arith.select", up, self.emit("arith.cmp", lb, ub, node=node, pred="lt"),
                             self.emit("arith.cmp", lb, ub, node=node, pred="gt"), node=node)  # fmt: skip
        # Non-empty: (ub - lb - sign) and step have one sign, so truncation is floor.
        span = self.emit("arith.sub", self.emit("arith.sub", ub, lb, node=node), sign, node=node)
        last = self.emit("arith.add", lb, self.emit("arith.mul", self.emit("arith.div", span, step,
                         node=node), step, node=node), node=node)  # fmt: skip
        start = self.emit("arith.select", nonempty, last, lb, node=node)
        end = self.emit("arith.select", nonempty, self.emit("arith.sub", lb, step, node=node), lb,
                        node=node)  # fmt: skip
        return [start, end, self.emit("arith.neg", step, node=node)]

    def unroll(self, node: ast.For, values: list[int]) -> None:
        if len(values) > MAX_UNROLL:
            raise self.error(KdslTypeError, f"static loop of {len(values)} iterations is too "
                             f"long to unroll (at most {MAX_UNROLL})", node.iter)  # fmt: skip
        name = node.target.id
        saved = {k: self.vars.get(k) for k in (BRK, CONT)}
        level = set().union(*(exits(s) for s in node.body)) if node.body else set()
        if BREAK in level:
            self.vars[BRK] = self.const(False, BOOL, node)
        stop_kinds = level & {BREAK, RETURN}
        self.loop_depth += 1

        def iteration(k: int) -> None:
            if k == len(values):
                return
            self.bind_raw(name, self.const(values[k], I32, node.target))
            if CONTINUE in level:
                self.vars[CONT] = self.const(False, BOOL, node)
            self.visit_body(node.body)
            guard = (
                self.flag_guard(stop_kinds, node) if stop_kinds and k + 1 < len(values) else None
            )
            if guard is not None:
                self.emit_if(guard, lambda: iteration(k + 1), None, node)
            else:
                iteration(k + 1)

        try:
            iteration(0)
        finally:
            self.loop_depth -= 1
        for k, v in saved.items():
            if v is None:
                self.vars.pop(k, None)
            else:
                self.vars[k] = v

    def visit_While(self, node: ast.While) -> None:
        if node.orelse:
            raise self.error(KdslSyntaxError, "while/else is not supported", node)
        self.loop_depth += 1
        try:
            carried, saved = self.loop_setup(node.body, None, node.test)

            def cond(vals: dict[str, Value]) -> Value:
                return self.to_bool(self.visit(node.test), node.test)

            self.lower_while(carried, saved, node.body, node, cond)
        finally:
            self.loop_depth -= 1

    def visit_Break(self, node: ast.Break) -> None:
        if self.loop_depth == 0:
            raise self.error(KdslSyntaxError, "'break' outside a loop", node)
        self.vars[BRK] = self.const(True, BOOL, node)

    def visit_Continue(self, node: ast.Continue) -> None:
        if self.loop_depth == 0:
            raise self.error(KdslSyntaxError, "'continue' outside a loop", node)
        self.vars[CONT] = self.const(True, BOOL, node)

    def visit_Return(self, node: ast.Return) -> None:
        values: list[Value] = []
        if node.value is not None:
            if self.kind == "kernel":
                raise self.error(KdslSyntaxError, "a kernel cannot return a value", node)
            got = self.visit(node.value)
            items = got if isinstance(got, tuple) else (got,)
            values = [self.value(v, node.value) for v in items]
        types = [v.type for v in values]
        if self.res_types is None:
            self.res_types = types
        elif self.res_types != types:
            raise self.error(
                KdslTypeError,
                f"this return gives ({', '.join(map(str, types))}) but an earlier return gives "
                f"({', '.join(map(str, self.res_types))}); every return must agree",
                node,
            )
        for k, v in enumerate(values):
            self.vars[f"$rv{k}"] = v
        if RET in self.vars:
            self.vars[RET] = self.const(True, BOOL, node)

    def tid(self, n: int, node: ast.AST) -> Any:
        if self.kind != "kernel":
            raise self.error(KdslSyntaxError, "tid() can only be used in a kernel", node)
        if not 1 <= n <= 4:
            raise self.error(KdslTypeError, f"tid() gives 1 to 4 indices, not {n}", node)
        if self.tid_ndim is not None and self.tid_ndim != n:
            raise self.error(
                KdslTypeError, f"tid() unpacked into {n} names here but {self.tid_ndim} before",
                node)  # fmt: skip
        self.tid_ndim = n
        vals = tuple(self.emit_typed("kd.tid", [], I32, node, dim=d, ndim=n) for d in range(n))
        return vals[0] if n == 1 else vals

    def visit_Global(self, node: ast.AST) -> None:
        raise self.error(KdslSyntaxError, "'global'/'nonlocal' are not supported in kernels", node)

    visit_Nonlocal = visit_Global

    def visit_Assert(self, node: ast.Assert) -> None:
        raise self.error(KdslSyntaxError, "assert is not supported in kernels", node)

    def undefined(self, name: str, node: ast.AST) -> None:
        raise self.error(KdslNameError, f"name '{name}' is not defined", node)


def _is_reversed_range(em, it: ast.expr) -> bool:
    """Whether ``it`` is ``reversed(range(...))`` (Python's or kdsl's ``reversed``)."""
    if not (isinstance(it, ast.Call) and isinstance(it.func, ast.Name | ast.Attribute)):
        return False
    fn = em.visit(it.func)
    if not (is_hashable(fn) and PYTHON_ALIASES.get(fn, fn) is BUILTINS["reversed"]):
        return False
    if it.keywords or len(it.args) != 1 or not isinstance(it.args[0], ast.Call):
        raise em.error(KdslSyntaxError, "reversed() in a for loop must wrap range(...)", it)
    return True


def _plain_base(node: ast.expr) -> bool:
    """A name, an attribute, or a row of one with plain indices (``a``, ``s.a``, ``a[i]``):
    evaluating it twice has no effect."""
    if isinstance(node, ast.Name | ast.Attribute):
        return True
    if isinstance(node, ast.Subscript):
        idx = node.slice.elts if isinstance(node.slice, ast.Tuple) else [node.slice]
        plain = all(isinstance(i, ast.Name | ast.Constant) for i in idx)
        return plain and isinstance(node.value, ast.Name | ast.Attribute)
    return False
