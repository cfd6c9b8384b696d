"""The reverse sweep: the kernel's ops walked backwards, each through its VJP rule.

``adj`` maps a kernel value to its adjoint so far (absent: zero); each op adds its
contributions to its operands' adjoints. Memory turns around: the adjoint of a read
``x[i]`` is added into the gradient array ``adj_x[i]`` (atomically unless the
thread owns the element), and a write ``y[i] = v`` reads ``adj_y[i]`` into ``v``'s
adjoint. An ``scf.if`` reverses into an ``scf.if`` over the same condition that
replays the branch that ran and reverses it; loops reverse over their tapes
(``reverse_loops``). Adjoint ops carry the location of their primal op.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from kdsl.errors import KdslError
from kdsl.ir import Block, Builder, Operation, Region, Value
from kdsl.ir.types import I64, StructType, Type
from kdsl.ir.vjp import VjpContext, get_rule, is_differentiable
from kdsl.passes.adjoint.analysis import Primal, base_array, defined_in
from kdsl.passes.adjoint.local_arrays import check_no_gradient
from kdsl.passes.adjoint.replay import Replay
from kdsl.passes.adjoint.reverse_loops import reverse_for, reverse_while
from kdsl.passes.adjoint.tapes import TapeWriter

Adjoints = dict[Value, Value]


@dataclass(eq=False)
class ReverseSweep:
    """Emits the reverse of a kernel's ops into its adjoint function.

    ``grads`` maps the kernel's differentiable array parameters to the adjoint
    function's gradient arrays; ``body`` is that function's block (the hidden
    ``grad_owned`` mask is added to it on first use).
    """

    primal: Primal
    b: Builder
    replay: Replay
    tapes: TapeWriter
    grads: dict[Value, Value]
    body: Block
    _grad_owned: Value | None = field(default=None, init=False)

    def reverse_block(self, block: Block, vmap: dict[Value, Value], adj: Adjoints) -> None:
        """Emit the reverse of ``block``'s ops (terminator excluded) into the builder."""
        for op in reversed(block.ops):
            if not op.opdef.is_terminator:
                with self.b.at(op.loc):
                    self.reverse_op(op, vmap, adj)

    def accumulate(self, adj: Adjoints, v: Value, g: Value | None) -> None:
        """Add the contribution ``g`` (None: zero) to the adjoint of ``v``."""
        if g is None or not is_differentiable(v.type):
            return
        if g.type != v.type:
            raise AssertionError(f"adjoint of {v.type} has type {g.type}")
        old = adj.get(v)
        adj[v] = g if old is None else self.add(old, g)

    def add(self, a: Value, g: Value) -> Value:
        """``a + g`` for adjoints; structs add field by field (``arith.add`` has no
        struct form), keeping ``a``'s non-differentiable fields (arrays, integers)."""
        if not isinstance(a.type, StructType):
            return self.b.value("arith.add", a, g)
        fields = []
        for name, ft in a.type.fields:
            part = self.b.value("struct.extract", a, field=name)
            if is_differentiable(ft):
                part = self.add(part, self.b.value("struct.extract", g, field=name))
            fields.append(part)
        return self.b.create("struct.construct", fields, [a.type]).result

    def zeros(self, t: Type) -> Value:
        """A zero of type ``t`` (the adjoint of a value nothing depends on)."""
        return VjpContext(self.b, lambda v: v).zeros(t)

    def reverse_op(self, op: Operation, vmap: dict[Value, Value], adj: Adjoints) -> None:
        """Emit the adjoint of one op: its VJP, or the reverse of its memory access or region."""
        name = op.name
        if name == "kd.load":
            self._reverse_load(op, vmap, adj)
        elif name in ("kd.store", "kd.atomic_rmw"):
            self._reverse_write(op, vmap, adj)
        elif name == "scf.if":
            self._reverse_if(op, vmap, adj)
        elif name in ("scf.for", "scf.while"):
            if self.primal.matters(op):
                (reverse_for if name == "scf.for" else reverse_while)(self, op, vmap, adj)
        elif name == "func.call":
            self._reverse_call(op, vmap, adj)
        elif (
            op.operands and op.opdef.is_pure and any(is_differentiable(r.type) for r in op.results)
        ):
            seeds = [adj.get(r) for r in op.results]
            if all(s is None for s in seeds):
                return
            rule = get_rule(name)
            if rule is None:
                raise KdslError(f"kdsl has no gradient for '{name}'", op.loc, self.primal.sym)
            ctx = VjpContext(self.b, vmap.__getitem__)
            contribs = rule(ctx, op, seeds)
            for operand, c in zip(op.operands, contribs):
                self.accumulate(adj, operand, c)

    def grad_of(self, arr: Value, vmap: dict[Value, Value]) -> Value | None:
        """The gradient array of ``arr``: a parameter's, the same view of its base's
        (``kd.array_view``, emitted here over the replayed indices), or the same field of
        its struct's adjoint (``struct.extract``: a struct parameter's adjoint holds its
        array fields' gradients); None when none."""
        grad = self.grads.get(arr)
        src = getattr(arr, "op", None)
        if grad is not None or src is None:
            return grad
        if src.name == "kd.array_view":
            base = self.grad_of(src.operands[0], vmap)
            if base is not None:
                grad = self.b.value("kd.array_view", base, *[vmap[i] for i in src.operands[1:]])
        elif src.name == "struct.extract":
            base = self.grad_of(src.operands[0], vmap)
            if base is not None:
                grad = self.b.value("struct.extract", base, field=src.attrs["field"])
        return grad

    def _reverse_load(self, op: Operation, vmap: dict[Value, Value], adj: Adjoints) -> None:
        b = self.b
        g = adj.get(op.results[0])
        if g is None:
            return
        grad = self.grad_of(op.operands[0], vmap)
        if grad is None:
            check_no_gradient(self.primal, op)
            return
        if isinstance(g.type, StructType):
            raise KdslError("kdsl cannot yet differentiate reads of struct arrays",
                            op.loc, self.primal.sym)  # fmt: skip
        idx = [vmap[i] for i in op.operands[1:]]
        if self.primal.exclusive(op.operands[0]):
            # Only this thread touches this element: a plain read-add-write.
            old = b.value("kd.load", grad, *idx)
            b.create("kd.store", [b.value("arith.add", old, g), grad, *idx])
        else:
            b.create("kd.atomic_rmw", [g, grad, *idx], attrs={"kind": "add"})

    def _reverse_call(self, op: Operation, vmap: dict[Value, Value], adj: Adjoints) -> None:
        """A call to a function with a custom gradient (``@kdsl.func_grad``).

        The gradient function takes the primal arguments and one adjoint per result,
        and returns one adjoint contribution per argument.
        """
        seeds = [adj.get(r) for r in op.results]
        if all(s is None for s in seeds):
            return
        module = self.primal.module
        grad = module.get_func(self.primal.callee(op).attrs["custom_grad"])
        args = [vmap[v] for v in op.operands]
        args += [s or self.zeros(r.type) for s, r in zip(seeds, op.results)]
        call = self.b.create("func.call", args, [v.type for v in op.operands],
                             {"callee": grad.attrs["sym_name"]})  # fmt: skip
        for operand, c in zip(op.operands, call.results):
            self.accumulate(adj, operand, c)

    def _reverse_write(self, op: Operation, vmap: dict[Value, Value], adj: Adjoints) -> None:
        v, arr = op.operands[0], op.operands[1]
        if not is_differentiable(v.type):
            return
        grad = self.grad_of(arr, vmap)
        if grad is None:
            return
        b = self.b
        idx = [vmap[i] for i in op.operands[2:]]
        g = b.value("kd.load", grad, *idx)
        kind = op.attrs.get("kind", "store")
        params = self.primal.block.args
        if kind == "sub":
            g = b.value("arith.neg", g)
        elif kind in ("min", "max"):
            # The value reached the array only if it is what the array holds now.
            now = b.value("kd.load", vmap[arr], *idx)
            g = b.value("arith.select", b.value("arith.cmp", now, vmap[v], pred="eq"), g,
                        self.zeros(v.type))  # fmt: skip
        elif kind in ("store", "exch") and base_array(arr) in params:
            self._consume(grad, idx, params.index(base_array(arr)), v.type)
        self.accumulate(adj, v, g)

    def _consume(self, grad: Value, idx: list[Value], param: int, t: Type) -> None:
        """Zero ``grad[idx]`` after a store's adjoint read it, if the runtime says so.

        A store overwrites the element, so the gradient of its old value is zero: the
        element's adjoint must be consumed for in-place updates to differentiate right.
        The runtime sets bit ``param`` of the hidden ``grad_owned`` mask when the
        gradient array is the array's own ``.grad`` (as Warp does); gradient buffers a
        caller passes explicitly are left as they were.
        """
        b = self.b
        if self._grad_owned is None:
            self._grad_owned = self.body.add_arg(I64, "grad_owned")
        bit = b.value("arith.and", b.value("arith.shr", self._grad_owned, b.constant(param, I64)),
                      b.constant(1, I64))  # fmt: skip
        owned = b.value("arith.cmp", bit, b.constant(0, I64), pred="ne")
        then, other = Block(), Block()
        with b.at_end(then):
            b.create("kd.store", [self.zeros(t), grad, *idx])
            b.create("scf.yield", [])
        with b.at_end(other):
            b.create("scf.yield", [])
        b.create("scf.if", [owned], [], regions=[Region(then), Region(other)])

    def _reverse_if(self, op: Operation, vmap: dict[Value, Value], adj: Adjoints) -> None:
        b = self.b
        inside = defined_in(op)
        branches: list[tuple[Block, Adjoints]] = []
        for region in op.regions:
            blk = Block()
            inner = dict(vmap)
            a = dict(adj)
            with b.at_end(blk):
                self.replay.replay(region.block, inner, record=True)
                for x, res in zip(region.block.terminator.operands, op.results):
                    self.accumulate(a, x, adj.get(res))
                self.reverse_block(region.block, inner, a)
            branches.append((blk, a))
        # The adjoints either branch changed leave the reversed if as its results.
        changed: dict[Value, None] = {}
        for _, a in branches:
            for k, v in a.items():
                if k not in inside and adj.get(k) is not v:
                    changed.setdefault(k, None)
        for blk, a in branches:
            with b.at_end(blk):
                outs = [a.get(k) or self.zeros(k.type) for k in changed]
                b.create("scf.yield", outs)
        new = b.create("scf.if", [vmap[op.operands[0]]], [k.type for k in changed],
                       regions=[Region(branches[0][0]), Region(branches[1][0])])  # fmt: skip
        for k, r in zip(changed, new.results):
            adj[k] = r
