"""Structured control flow: ``scf.if`` merges, loops with carried values, exit flags.

SSA construction follows Triton: each branch or loop body is lowered with a copy of
the scope; afterwards the names whose values differ become results of the ``scf``
op. Loop-carried names come from the AST pre-pass (``analysis.assigned_names``), so
no body is visited twice.

``break``, ``continue`` and ``return`` set flag variables (``$brk``, ``$cont``,
``$ret``; returned values go to ``$rv0``...). Statements after one that may exit
are wrapped in ``scf.if`` on the flags, and a loop that may break or return becomes
an ``scf.while`` whose condition checks them. Names starting with ``$`` are the
frontend's own: a branch that leaves one unset yields a zero (never read, the flag
guards it) instead of marking it "may be unassigned".
"""

from __future__ import annotations

import ast
from collections.abc import Callable
from typing import Any

from kdsl.errors import KdslSyntaxError, KdslTypeError
from kdsl.frontend.analysis import (
    BREAK,
    CONTINUE,
    RETURN,
    assigned_names,
    body_exits,
    call_rebinds,
    exits,
)
from kdsl.frontend.expressions import ExpressionLowering
from kdsl.frontend.inout import inout_positions, static_callee
from kdsl.frontend.structs import has_zero, zero_value
from kdsl.frontend.values import default_type
from kdsl.ir import Block, Region, Value
from kdsl.ir.rewrite import constant_of
from kdsl.ir.types import BOOL, F32, I32, StructType, Type

BRK, CONT, RET = "$brk", "$cont", "$ret"
MAX_UNROLL = 4096


class ControlFlowLowering(ExpressionLowering):
    """Branches and loops; ``visit_body`` inserts the exit-flag guards."""

    def visit_body(self, stmts: list[ast.stmt]) -> None:
        raise NotImplementedError

    # --- branches -----------------------------------------------------------------

    def in_block(self, block: Block, fn: Callable[[], Any]) -> Any:
        with self.b.at_end(block):
            return fn()

    def branch(self, fn: Callable[[], None] | None) -> tuple[Block, dict[str, Value], set[str]]:
        """Lower ``fn`` into a new block with a copy of the current scope."""
        saved_vars, saved_maybe = self.vars, self.maybe
        self.vars, self.maybe = dict(saved_vars), set(saved_maybe)
        block = Block()
        try:
            if fn is not None:
                self.in_block(block, fn)
            return block, self.vars, self.maybe
        finally:
            self.vars, self.maybe = saved_vars, saved_maybe

    def emit_if(self, cond: Value, then_fn, else_fn, node: ast.AST) -> None:
        """``if cond: then_fn() else: else_fn()``, merging the variables they assign."""
        then_b, then_v, then_m = self.branch(then_fn)
        else_b, else_v, else_m = self.branch(else_fn)
        maybe = then_m | else_m
        merged: list[tuple[str, Value, Value]] = []
        for name in sorted(set(then_v) | set(else_v)):
            tv, ev = then_v.get(name), else_v.get(name)
            if tv is ev:
                # Both branches bound the name to one value from before the if
                # (`if c: return a` / `return a`): no merge, but it is bound now.
                if tv is not None and self.vars.get(name) is not tv:
                    self.bind_raw(name, tv)
                continue
            if tv is None or ev is None:
                if not name.startswith("$"):
                    maybe.add(name)
                    self.vars.pop(name, None)
                    continue
                known = tv if tv is not None else ev
                fill_block = then_b if tv is None else else_b
                zero = self.in_block(fill_block, lambda t=known.type: self.zero(t, node))
                tv, ev = (zero, ev) if tv is None else (tv, zero)
            if tv.type != ev.type:
                raise self.error(
                    KdslTypeError,
                    f"variable '{name}' is {tv.type} on one branch and {ev.type} on the other; "
                    "a variable must keep one type",
                    node,
                )
            merged.append((name, tv, ev))
        for block, k in ((then_b, 1), (else_b, 2)):
            self.in_block(block, lambda k=k: self.b.create("scf.yield", [m[k] for m in merged]))
        op = self.b.create(
            "scf.if", [cond], [m[1].type for m in merged],
            regions=[Region(then_b), Region(else_b)], loc=self.loc(node),
        )  # fmt: skip
        for (name, _, _), res in zip(merged, op.results):
            self.bind_raw(name, res)
        self.maybe = maybe - set(self.vars)

    def if_value(self, cond: Value, then_fn, else_fn, node: ast.AST, t: Type | None) -> Value:
        """An expression-level ``scf.if`` with one result (``and``/``or``/ternary).

        An arm may rebind variables through an in-out call (``randf(state)``): those
        become extra results, so the state advances only on the arm that ran.
        """
        arms: dict[str, Any] = {}
        then_b, then_v, _ = self.branch(lambda: arms.__setitem__("t", then_fn()))
        else_b, else_v, _ = self.branch(lambda: arms.__setitem__("e", else_fn()))
        tv, ev = arms["t"], arms["e"]
        changed = sorted(n for n in then_v.keys() & else_v.keys() & self.vars.keys()
                         if then_v[n] is not else_v[n])  # fmt: skip
        if t is None:
            if isinstance(tv, Value) or isinstance(ev, Value):
                t = tv.type if isinstance(tv, Value) else ev.type
            else:
                t = F32 if isinstance(tv, float) or isinstance(ev, float) else default_type(tv)
        tv = self.in_block(then_b, lambda: self.value(tv, node, want=t))
        ev = self.in_block(else_b, lambda: self.value(ev, node, want=t))
        if tv.type != ev.type:
            raise self.error(
                KdslTypeError, f"both arms must have one type, got {tv.type} and {ev.type}", node
            )
        for block, v, scope in ((then_b, tv, then_v), (else_b, ev, else_v)):
            yielded = [v, *(scope[n] for n in changed)]
            self.in_block(block, lambda y=yielded: self.b.create("scf.yield", y))
        types = [tv.type, *(self.vars[n].type for n in changed)]
        op = self.b.create("scf.if", [cond], types, regions=[Region(then_b), Region(else_b)],
                           loc=self.loc(node))  # fmt: skip
        for n, r in zip(changed, op.results[1:]):
            self.bind_raw(n, r)
        return op.results[0]

    def bind_raw(self, name: str, v: Value) -> None:
        if not name.startswith("$") and v.name_hint is None:
            v.name_hint = name
        self.vars[name] = v
        self.maybe.discard(name)

    def flag_guard(self, kinds: set[str], node: ast.AST) -> Value | None:
        """``not (flags)`` for the exit kinds given, or None when no flag is set up."""
        names = {RETURN: RET, BREAK: BRK, CONTINUE: CONT}
        flags = [self.vars[names[k]] for k in sorted(kinds) if names[k] in self.vars]
        if not flags:
            return None
        any_set = flags[0]
        for f in flags[1:]:
            any_set = self.emit("arith.or", any_set, f, node=node)
        return self.emit("arith.not", any_set, node=node)

    # --- loops --------------------------------------------------------------------

    def call_inout_positions(self, call: ast.Call) -> set[int]:
        """Argument positions of ``call`` its callee may write back (``inout.py``)."""
        fn = static_callee(call.func, set(self.vars) | self.maybe, self.globals)
        return inout_positions(fn, len(call.args)) if fn is not None else set()

    def loop_setup(
        self, body: list[ast.stmt], target: str | None, test: ast.expr | None = None
    ) -> tuple[list[str], dict]:
        """Carried names (assigned in the body or the test, live before) and the saved flags."""
        saved = {k: self.vars.get(k) for k in (BRK, CONT)}
        level = body_exits(body)
        if BREAK in level:
            self.vars[BRK] = self.const(False, BOOL)
        else:
            self.vars.pop(BRK, None)
        self.vars.pop(CONT, None)
        # Stores into array elements (`out[i] = x`) do not rebind the array name.
        written = assigned_names(body)
        written |= call_rebinds([*body, *([test] if test else [])], self.call_inout_positions)
        carried = sorted(
            n for n in written if n in self.vars and n != target and self.vars[n].type.is_value
        )
        for flag in (BRK, RET):
            if flag in self.vars and (flag == BRK or RETURN in level):
                carried.append(flag)
        return carried, saved

    def loop_body(self, block: Block, carried: list[str], body, target, iv, node):
        """Lower a loop body into ``block`` (args: [iv,] carried). Returns its scope."""
        saved_vars, saved_maybe = self.vars, self.maybe
        self.vars, self.maybe = dict(saved_vars), set(saved_maybe)
        offset = len(block.args) - len(carried)
        for n, arg in zip(carried, block.args[offset:]):
            self.bind_raw(n, arg)
        if target is not None and iv is not None:
            self.bind_raw(target, iv)
        if CONTINUE in body_exits(body):
            self.vars[CONT] = self.in_block(block, lambda: self.const(False, BOOL, node))
        self.in_block(block, lambda: self.visit_body(body))
        scope = self.vars, self.maybe
        self.vars, self.maybe = saved_vars, saved_maybe
        return scope

    def finish_loop(self, carried, results, body_vars, body_maybe, saved, target) -> None:
        for n, r in zip(carried, results):
            self.bind_raw(n, r)
        new = (set(body_vars) - set(self.vars)) | (body_maybe - set(self.vars))
        self.maybe |= {n for n in new if not n.startswith("$")}
        if target is not None:
            self.vars.pop(target, None)
            self.maybe.add(target)
        for k, v in saved.items():
            if v is None:
                self.vars.pop(k, None)
            else:
                self.vars[k] = v

    def assigned_by_every_run(self, bounds, carried, body_vars, body_maybe, target) -> list[str]:
        """Names first assigned in the body of a loop that surely runs (constant bounds, at
        least one iteration; the caller has no early exit) and that every iteration
        assigns: as in Python (and Warp), they hold the last iteration's value after it.

        They become loop-carried values that start as zeros nobody reads: each iteration
        assigns them before the loop yields.
        """
        consts = [constant_of(v) for v in bounds]
        if not all(ok for ok, _ in consts):
            return []
        lb, ub, step = (c for _, c in consts)
        if step == 0 or len(range(lb, ub, step)) == 0:
            return []
        return [n for n in sorted(body_vars)
                if n not in self.vars and n not in carried and n not in body_maybe
                and n != target and not n.startswith("$") and body_vars[n].type.is_value]  # fmt: skip

    def late_carried(self, carried: list[str], body_vars: dict[str, Value], node) -> list[str]:
        """``$rv`` values first set inside the body: carried too, starting as zeros."""
        return [n for n in sorted(body_vars) if n.startswith("$rv") and n not in self.vars
                and n not in carried]  # fmt: skip

    def lower_range_for(self, target: str, bounds: list[Value], body, node: ast.For) -> None:
        lb, ub, step = bounds
        carried, saved = self.loop_setup(body, target)
        if exits_loop(body):
            self.lower_range_as_while(target, lb, ub, step, carried, saved, body, node)
            return
        init = [self.vars[n] for n in carried]
        block = Block([I32] + [v.type for v in init], [target] + [None] * len(init))
        body_vars, body_maybe = self.loop_body(block, carried, body, target, block.args[0], node)
        for n in self.assigned_by_every_run(bounds, carried, body_vars, body_maybe, target):
            t = body_vars[n].type
            if isinstance(t, StructType) and not has_zero(t):
                continue  # a struct holding arrays has no zero to start from
            block.add_arg(t)
            init.append(zero_value(self, t, node, n))
            carried = [*carried, n]
        self.check_carried(carried, body_vars, node)
        self.in_block(block, lambda: self.b.create("scf.yield", [body_vars[n] for n in carried]))
        op = self.b.create("scf.for", [lb, ub, step, *init], [v.type for v in init],
                           regions=[Region(block)], loc=self.loc(node))  # fmt: skip
        self.finish_loop(carried, op.results, body_vars, body_maybe, saved, target)

    def lower_range_as_while(self, target, lb, ub, step, carried, saved, body, node) -> None:
        # One counter name per nesting level: an inner loop lowered this way must not
        # rebind (and then drop) the counter of the loop around it.
        name = f"$iv{sum(n.startswith('$iv') for n in self.vars)}"
        self.vars[name] = lb
        carried = [name, *carried]

        def cond(vals: dict[str, Value]) -> Value:
            iv = vals[name]
            up = self.emit("arith.cmp", iv, ub, node=node, pred="lt")
            down = self.emit("arith.cmp", iv, ub, node=node, pred="gt")
            pos = self.emit("arith.cmp", step, self.const(0, I32, node), node=node, pred="gt")
            return self.emit("arith.select", pos, up, down, node=node)

        def step_fn(vals: dict[str, Value]) -> None:
            vals[name] = self.emit("arith.add", vals[name], step, node=node)

        self.lower_while(carried, saved, body, node, cond, target, step_fn)
        self.vars.pop(name, None)

    def lower_while(self, carried, saved, body, node, cond_fn, target=None, step_fn=None) -> None:
        """An ``scf.while``: the condition (and the exit flags) in the before region."""
        init = [self.vars[n] for n in carried]
        after = Block([v.type for v in init])
        iv = after.args[0] if target is not None else None
        body_vars, body_maybe = self.loop_body(after, carried, body, target, iv, node)
        extra = self.late_carried(carried, body_vars, node)
        for n in extra:
            after.add_arg(body_vars[n].type)
            init.append(self.zero(body_vars[n].type, node))
        carried = carried + extra
        self.check_carried(carried, body_vars, node)
        if step_fn is not None:
            self.in_block(after, lambda: step_fn(body_vars))
        self.in_block(after, lambda: self.b.create("scf.yield", [body_vars[n] for n in carried]))
        before = Block([v.type for v in init])
        self.in_block(before, lambda: self.while_condition(before, carried, cond_fn, node))
        op = self.b.create("scf.while", init, [v.type for v in init],
                           regions=[Region(before), Region(after)], loc=self.loc(node))  # fmt: skip
        self.finish_loop(carried, op.results, body_vars, body_maybe, saved, target)

    def while_condition(self, before: Block, carried, cond_fn, node) -> None:
        saved_vars = self.vars
        self.vars = dict(saved_vars)
        for n, arg in zip(carried, before.args):
            self.bind_raw(n, arg)
        try:
            flags = [self.vars[f] for f in (BRK, RET) if f in carried]
            if flags:
                stop = flags[0]
                for f in flags[1:]:
                    stop = self.emit("arith.or", stop, f, node=node)
                c = self.if_value(stop, lambda: False, lambda: cond_fn(self.vars), node, BOOL)
            else:
                c = cond_fn(self.vars)
            # The test may rebind carried names (an in-out call such as randf(state)):
            # the body and the loop's results see the values it leaves.
            self.b.create("scf.condition", [c, *(self.vars[n] for n in carried)])
        finally:
            self.vars = saved_vars

    def check_carried(self, carried: list[str], body_vars: dict[str, Value], node) -> None:
        for n in carried:
            if n not in body_vars:
                raise self.error(KdslSyntaxError, f"internal: loop variable {n} lost", node)


def exits_loop(body: list[ast.stmt]) -> bool:
    """True when a loop body may break out or return (it then needs ``scf.while``)."""
    level = set()
    for s in body:
        level |= exits(s)
    return bool(level & {BREAK, RETURN})
