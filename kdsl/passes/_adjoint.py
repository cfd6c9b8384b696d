"""The reverse-mode transformation behind the ``adjoint`` pass.

``AdjointBuilder(module, kernel).build()`` adds the kernel's adjoint function and,
when it has loops whose trip count is only known at run time, a counting function.
Strategy (documented for users in ``docs/autodiff.md``):

- **Forward replay, then reverse sweep.** The adjoint function first recomputes the
  kernel's values (stores and atomics are skipped: the outputs already hold them),
  then walks the ops backwards applying each op's VJP rule from the catalog. Reads
  of an array become atomic adds into its gradient array; writes read the output's
  gradient.
- **Regions recompute.** Values inside an ``scf.if`` branch or a loop body are not
  visible outside it, so the reverse of a region first replays the region (from
  its arguments) and then reverses it. ``if`` reverses the branch that ran.
- **Loops tape their carried values.** Replaying a loop stores the values it carries
  into each iteration (all of them, ints and flags included) in a per-thread tape:
  hidden 2-d arrays ``[thread, iteration]`` of the adjoint function. The reverse loop
  runs the iterations backwards, reloads iteration k's carried values, replays the
  body from them and reverses it. ``while`` loops (and the flags ``break`` and
  ``continue`` become) are handled the same way, so loop-carried gradients are exact.
  A loop nested in another is taped again inside each reversed outer iteration, so
  its tape holds one instance at a time.
- **Tape sizes.** A loop with constant bounds has a static size. Otherwise the
  counting function (the kernel with its side effects removed and each loop's trip
  count reduced with an atomic max) runs first and the runtime allocates exactly
  what the adjoint needs, refusing with a clear error above a memory limit. A
  mismatch at run time (possible only with nondeterministic control flow) sets a
  status flag the runtime turns into an error: a gradient is never silently wrong.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable
from dataclasses import dataclass, field

from kdsl.errors import KdslError, render_loc
from kdsl.ir import Block, Builder, Module, Operation, Region, Value, new_func
from kdsl.ir.types import BOOL, I8, I32, I64, ArrayType, StructType, Type
from kdsl.ir.vjp import VjpContext, get_rule, is_differentiable

ADJ_SUFFIX = "__adj"
#: Ops the forward replay skips: their effects happened in the forward launch
#: (``kd.atomic_cas`` and ``kd.print`` are not differentiable either).
_SIDE_EFFECTS = frozenset({"kd.store", "kd.atomic_rmw", "kd.atomic_cas", "kd.print"})
COUNT_SUFFIX = "__count"


class KdslGradientWarning(UserWarning):
    """A differentiable kernel whose gradient may be wrong (e.g. it reads an array it wrote)."""


@dataclass
class LoopTape:
    """The tape of one loop: hidden array parameters holding its carried values."""

    index: int
    op: Operation
    leaves: list[Type]
    static_slots: int | None
    params: list[Value] = field(default_factory=list)

    @property
    def site(self) -> str:
        return str(self.op.loc)


def _leaf_types(t: Type) -> list[Type]:
    """Storage types of one carried value: structs flatten, bools store as i8."""
    if isinstance(t, StructType):
        return [leaf for _, ft in t.fields for leaf in _leaf_types(ft)]
    if isinstance(t, ArrayType) or not t.is_value:
        raise TypeError(t)
    return [I8 if t == BOOL else t]


def _constant(v: Value) -> int | None:
    op = getattr(v, "op", None)
    if op is not None and op.name == "arith.constant":
        return int(op.attrs["value"])
    return None


def _static_trips(op: Operation) -> int | None:
    if op.name != "scf.for":
        return None
    lb, ub, st = (_constant(v) for v in op.operands[:3])
    if lb is None or ub is None or st is None:
        return None
    return len(range(lb, ub, st)) if st != 0 else 0


def _is_tid(v: Value, dim: int, ndim: int) -> bool:
    """``v`` is component ``dim`` of an ``ndim``-d thread index (1-d: the linear index)."""
    op = getattr(v, "op", None)
    return (
        op is not None
        and op.name == "kd.tid"
        and op.attrs["dim"] == dim
        and op.attrs["ndim"] == ndim
    )


def _defined_in(op: Operation) -> set[Value]:
    out: set[Value] = set()
    for inner in op.walk():
        if inner is not op:
            out.update(inner.results)
        for r in inner.regions:
            out.update(r.block.args)
    return out


def _outer_uses(op: Operation) -> list[Value]:
    """Differentiable values defined outside ``op`` that ops inside it use, in order."""
    inside = _defined_in(op)
    seen: dict[Value, None] = {}
    for inner in op.walk():
        if inner is op:
            continue
        for v in inner.operands:
            if v not in inside and is_differentiable(v.type):
                seen.setdefault(v, None)
    return list(seen)


class AdjointBuilder:
    """Builds ``<kernel>__adj`` (and ``<kernel>__count``) next to a kernel (see module doc)."""

    def __init__(self, module: Module, kernel: Operation) -> None:
        self.module = module
        self.fwd = kernel
        self.sym = kernel.attrs["sym_name"]
        self.fblock = kernel.regions[0].block
        self.tapes: list[LoopTape] = []
        self.tape_of: dict[Operation, LoopTape] = {}
        self.trips: dict[Operation, Value] = {}
        self.adj_arrays: dict[Value, Value] = {}
        self._matters: dict[Operation, bool] = {}
        self._owned: dict[Value, bool] = {}
        self.counting = False

    # -- entry points ------------------------------------------------------------
    def build(self) -> Operation:
        """Add and return the adjoint function."""
        self._check_supported()
        args = self.fblock.args
        types = [a.type for a in args]
        names = [a.name_hint for a in args]
        adj_names = [f"adj_{n or i}" for i, n in enumerate(names)]
        func = new_func(
            self.module, self.sym + ADJ_SUFFIX, types + types, names + adj_names, [], "kernel",
            self.fwd.loc, {"adjoint_of": self.sym},
        )  # fmt: skip
        body = func.regions[0].block
        self.func, self.body = func, body
        n = len(args)
        # Hidden parameters (tapes, flags) follow the 2n parameters and adjoints.
        func.attrs["hidden_from"] = 2 * n
        vmap: dict[Value, Value] = {a: body.args[i] for i, a in enumerate(args)}
        for i, a in enumerate(args):
            if isinstance(a.type, ArrayType) and is_differentiable(a.type.dtype):
                self.adj_arrays[a] = body.args[n + i]
        self.b = Builder(body)
        with self.b.at(self.fwd.loc):
            self.ltid = self.b.create("kd.tid", [], [I32], {"dim": 0, "ndim": 1}).result
        self.replay(self.fblock, vmap, record=True)
        self.reverse_block(self.fblock, vmap, {})
        self.b.create("func.return", loc=self.fwd.loc)
        self._finish_tapes()
        return func

    def build_counter(self) -> Operation | None:
        """Add the counting function, or return None when every tape size is static."""
        if all(t.static_slots is not None for t in self.tapes):
            return None
        self.counting = True
        args = self.fblock.args
        func = new_func(
            self.module, self.sym + COUNT_SUFFIX, [a.type for a in args] + [ArrayType(I32, 1)],
            [a.name_hint for a in args] + ["tape_slots"], [], "kernel", self.fwd.loc,
            {"counter_of": self.sym},
        )  # fmt: skip
        body = func.regions[0].block
        self.count_array = body.args[-1]
        vmap = {a: body.args[i] for i, a in enumerate(args)}
        self.b = Builder(body)
        self.replay(self.fblock, vmap, record=True)
        self.b.create("func.return", loc=self.fwd.loc)
        return func

    # -- checks --------------------------------------------------------------------
    def _check_supported(self) -> None:
        written: set[Value] = set()
        for op in self.fwd.walk():
            if op.name == "func.call" and not self._callee(op).attrs.get("custom_grad"):
                raise KdslError(
                    f"kdsl cannot differentiate a call to '{op.attrs['callee']}' that was not "
                    "inlined (recursive functions have no adjoint)", op.loc, self.sym)
            if op.name in ("kd.atomic_rmw", "kd.atomic_cas") and op.results[0].uses:
                kind = op.attrs.get("kind", "cas")
                raise KdslError(
                    f"the value returned by atomic_{kind} is used, and the backward "
                    "pass cannot replay it; launch this kernel with enable_backward=False or "
                    "stop using the returned value", op.loc, self.sym)  # fmt: skip
            if op.name in ("kd.store", "kd.atomic_rmw"):
                written.add(op.operands[1])
            elif op.name == "kd.atomic_cas":
                written.add(op.operands[2])
            elif op.name == "kd.load" and op.operands[0] in written:
                arr = op.operands[0]
                if arr in self.fblock.args and is_differentiable(arr.type.dtype):
                    warnings.warn(
                        f"kernel reads array '{arr.name_hint}' after writing it; its gradient "
                        "replays the read with the written value and may be wrong\n"
                        + render_loc(op.loc, self.sym), KdslGradientWarning, stacklevel=2)
                    written.discard(arr)  # warn once per array

    # -- forward replay -----------------------------------------------------------
    def matters(self, op: Operation) -> bool:
        """Whether a loop can contribute to any gradient (else it is not reversed)."""
        hit = self._matters.get(op)
        if hit is None:
            hit = any(
                is_differentiable(r.type) for r in op.results
            ) or any(
                inner.name in ("kd.load", "kd.store", "kd.atomic_rmw")
                and inner.operands[0 if inner.name == "kd.load" else 1] in self.adj_arrays
                for inner in op.walk()
            )  # fmt: skip
            self._matters[op] = hit
        return hit

    def replay(self, block: Block, vmap: dict[Value, Value], record: bool) -> list[Value]:
        """Clone ``block``'s ops at the builder (no side effects); give the terminator's operands."""
        for op in block.ops:
            if op.opdef.is_terminator:
                return [vmap[v] for v in op.operands]
            self.replay_op(op, vmap, record)
        return []

    def replay_op(self, op: Operation, vmap: dict[Value, Value], record: bool) -> None:
        name = op.name
        if name in _SIDE_EFFECTS:
            return
        b = self.b
        with b.at(op.loc):
            if name == "scf.if":
                regions = [self._replay_region(r.block, vmap, []) for r in op.regions]
                new = b.create("scf.if", [vmap[op.operands[0]]], [r.type for r in op.results],
                               regions=regions)  # fmt: skip
            elif name in ("scf.for", "scf.while") and (record or self.counting) and self.matters(op):
                self._replay_loop_taped(op, vmap)
                return
            elif name == "scf.for":
                body = op.regions[0].block
                region = self._replay_region(body, vmap, [a.type for a in body.args])
                new = b.create("scf.for", [vmap[v] for v in op.operands],
                               [r.type for r in op.results], regions=[region])  # fmt: skip
            elif name == "scf.while":
                before, after = op.regions
                regions = [
                    self._replay_region(before.block, vmap, [a.type for a in before.block.args]),
                    self._replay_region(after.block, vmap, [a.type for a in after.block.args]),
                ]
                new = b.create("scf.while", [vmap[v] for v in op.operands],
                               [r.type for r in op.results], regions=regions)  # fmt: skip
            else:
                attrs = dict(op.attrs)
                if name == "func.call":
                    attrs["callee"] = self._callee(op).attrs.get("custom_replay", attrs["callee"])
                new = Operation(op.opdef, [vmap[v] for v in op.operands],
                                [r.type for r in op.results], attrs, (), op.loc)  # fmt: skip
                b.insert(new)
        for old, r in zip(op.results, new.results):
            r.name_hint = old.name_hint
            vmap[old] = r

    def _replay_region(self, block: Block, vmap: dict[Value, Value], arg_types) -> Region:
        """A new region replaying ``block`` (its args become the new block's args)."""
        new = Block(arg_types, [a.name_hint for a in block.args])
        inner = dict(vmap)
        inner.update(zip(block.args, new.args))
        term = block.terminator
        with self.b.at_end(new):
            outs = self.replay(block, inner, record=False)
            self.b.create(term.name, outs, loc=term.loc)
        return Region(new)

    def _replay_loop_taped(self, op: Operation, vmap: dict[Value, Value]) -> None:
        """Replay a loop with an iteration counter, taping carried values (or counting)."""
        b = self.b
        tape = self._tape(op)
        zero = b.constant(0, I32)
        one = b.constant(1, I32)
        if op.name == "scf.for":
            body = op.regions[0].block
            new_body = Block([a.type for a in body.args] + [I32],
                             [a.name_hint for a in body.args] + ["k"])  # fmt: skip
            inner = dict(vmap)
            inner.update(zip(body.args, new_body.args))
            k = new_body.args[-1]
            with b.at_end(new_body):
                self._store_tape(tape, k, new_body.args[1:-1])
                outs = self.replay(body, inner, record=False)
                b.create("scf.yield", [*outs, b.value("arith.add", k, one)])
            new = b.create("scf.for", [vmap[v] for v in op.operands] + [zero],
                           [r.type for r in op.results] + [I32], regions=[Region(new_body)])
            slots = new.results[-1]
        else:
            before, after = op.regions[0].block, op.regions[1].block
            nb = Block([a.type for a in before.args] + [I32],
                       [a.name_hint for a in before.args] + ["k"])  # fmt: skip
            na = Block([a.type for a in after.args] + [I32],
                       [a.name_hint for a in after.args] + ["k"])  # fmt: skip
            inner = dict(vmap)
            inner.update(zip(before.args, nb.args))
            with b.at_end(nb):
                self._store_tape(tape, nb.args[-1], nb.args[:-1])
                outs = self.replay(before, inner, record=False)
                b.create("scf.condition", [*outs, nb.args[-1]])
            inner = dict(vmap)
            inner.update(zip(after.args, na.args))
            with b.at_end(na):
                outs = self.replay(after, inner, record=False)
                b.create("scf.yield", [*outs, b.value("arith.add", na.args[-1], one)])
            new = b.create("scf.while", [vmap[v] for v in op.operands] + [zero],
                           [r.type for r in op.results] + [I32], regions=[Region(nb), Region(na)])
            slots = b.value("arith.add", new.results[-1], one)  # the before region ran N+1 times
        for old, r in zip(op.results, new.results):
            r.name_hint = old.name_hint
            vmap[old] = r
        self.trips[op] = new.results[-1]
        if self.counting and tape.static_slots is None:
            b.create("kd.atomic_rmw", [slots, self.count_array, b.constant(tape.index, I32)],
                     attrs={"kind": "max"})  # fmt: skip

    # -- tapes -----------------------------------------------------------------------
    def _carried(self, op: Operation) -> list[Value]:
        block = op.regions[0].block
        return list(block.args[1:] if op.name == "scf.for" else block.args)

    def _tape(self, op: Operation) -> LoopTape:
        tape = self.tape_of.get(op)
        if tape is None:
            leaves: list[Type] = []
            for v in self._carried(op):
                try:
                    leaves += _leaf_types(v.type)
                except TypeError:
                    raise KdslError(
                        f"kdsl cannot differentiate a loop that carries a {v.type} value "
                        f"('{v.name_hint or '?'}') from one iteration to the next",
                        op.loc, self.sym) from None  # fmt: skip
            static = _static_trips(op)
            tape = LoopTape(len(self.tapes), op, leaves, static)
            self.tapes.append(tape)
            self.tape_of[op] = tape
            if not self.counting:
                for j, t in enumerate(leaves):
                    tape.params.append(self.body.add_arg(ArrayType(t, 2), f"tape{tape.index}_{j}"))
        return tape

    def _flatten(self, v: Value) -> list[Value]:
        t = v.type
        if isinstance(t, StructType):
            return [leaf for i, (fname, _) in enumerate(t.fields)
                    for leaf in self._flatten(self.b.value("struct.extract", v, field=fname))]  # fmt: skip
        if t == BOOL:
            return [self.b.create("arith.cast", [v], [I8]).result]
        return [v]

    def _unflatten(self, t: Type, leaves: list[Value]) -> Value:
        if isinstance(t, StructType):
            return self.b.create(
                "struct.construct", [self._unflatten(ft, leaves) for _, ft in t.fields], [t]
            ).result
        v = leaves.pop(0)
        if t == BOOL:
            return self.b.create("arith.cast", [v], [BOOL]).result
        return v

    def _store_tape(self, tape: LoopTape, k: Value, values: Iterable[Value]) -> None:
        if self.counting:
            return
        b = self.b
        leaves = [leaf for v in values for leaf in self._flatten(v)]
        if not leaves:
            return
        cap = b.value("kd.array_shape", tape.params[0], dim=1)
        fits = b.value("arith.cmp", k, cap, pred="lt")
        then, other = Block(), Block()
        with b.at_end(then):
            for leaf, arr in zip(leaves, tape.params):
                b.create("kd.store", [leaf, arr, self.ltid, k])
            b.create("scf.yield", [])
        with b.at_end(other):
            b.create("kd.store", [b.constant(1, I32), self._status(), b.constant(0, I32)])
            b.create("scf.yield", [])
        b.create("scf.if", [fits], [], {"tape_guard": tape.index},
                 regions=[Region(then), Region(other)])  # fmt: skip

    def _load_tape(self, tape: LoopTape, k: Value, types: list[Type]) -> list[Value]:
        leaves = [self.b.value("kd.load", arr, self.ltid, k) for arr in tape.params]
        return [self._unflatten(t, leaves) for t in types]

    def _status(self) -> Value:
        if not hasattr(self, "status"):
            self.status = self.body.add_arg(ArrayType(I32, 1), "tape_status")
        return self.status

    def _finish_tapes(self) -> None:
        """Record the tape layout on the adjoint function for the runtime."""
        if self.tapes and not hasattr(self, "status"):
            self._status()
        self.func.attrs["tape_leaves"] = [len(t.leaves) for t in self.tapes]
        self.func.attrs["tape_slots"] = [
            -1 if t.static_slots is None else t.static_slots for t in self.tapes
        ]
        self.func.attrs["tape_sites"] = [t.site for t in self.tapes]

    # -- reverse sweep ---------------------------------------------------------------
    def reverse_block(self, block: Block, vmap: dict[Value, Value], adj: dict[Value, Value]) -> None:
        """Emit the reverse of ``block``'s ops (terminator excluded) into the builder."""
        for op in reversed(block.ops):
            if not op.opdef.is_terminator:
                with self.b.at(op.loc):
                    self.reverse_op(op, vmap, adj)

    def _acc(self, adj: dict[Value, Value], v: Value, g: Value | None) -> None:
        if g is None or not is_differentiable(v.type):
            return
        if g.type != v.type:
            raise AssertionError(f"adjoint of {v.type} has type {g.type}")
        old = adj.get(v)
        adj[v] = g if old is None else self.b.value("arith.add", old, g)

    def _zeros(self, t: Type) -> Value:
        return VjpContext(self.b, lambda v: v).zeros(t)

    def reverse_op(self, op: Operation, vmap: dict[Value, Value], adj: dict[Value, Value]) -> None:
        name = op.name
        b = self.b
        if name == "kd.load":
            g = adj.get(op.results[0])
            grad = self.adj_arrays.get(op.operands[0])
            if g is None or grad is None:
                return
            if isinstance(g.type, StructType):
                raise KdslError("kdsl cannot yet differentiate reads of struct arrays",
                                op.loc, self.sym)  # fmt: skip
            idx = [vmap[i] for i in op.operands[1:]]
            if self._exclusive(op.operands[0]):
                # Only this thread touches this element: a plain read-add-write.
                old = b.value("kd.load", grad, *idx)
                b.create("kd.store", [b.value("arith.add", old, g), grad, *idx])
            else:
                b.create("kd.atomic_rmw", [g, grad, *idx], attrs={"kind": "add"})
        elif name in ("kd.store", "kd.atomic_rmw"):
            self._reverse_write(op, vmap, adj)
        elif name == "scf.if":
            self._reverse_if(op, vmap, adj)
        elif name in ("scf.for", "scf.while"):
            if self.matters(op):
                (self._reverse_for if name == "scf.for" else self._reverse_while)(op, vmap, adj)
        elif name == "func.call":
            self._reverse_call(op, vmap, adj)
        elif op.operands and op.opdef.is_pure and any(
            is_differentiable(r.type) for r in op.results
        ):
            seeds = [adj.get(r) for r in op.results]
            if all(s is None for s in seeds):
                return
            rule = get_rule(name)
            if rule is None:
                raise KdslError(f"kdsl has no gradient for '{name}'", op.loc, self.sym)
            ctx = VjpContext(b, vmap.__getitem__)
            contribs = rule(ctx, op, seeds)
            for operand, c in zip(op.operands, contribs):
                self._acc(adj, operand, c)

    def _exclusive(self, arr: Value) -> bool:
        """Whether every access to ``arr`` indexes it by the thread index itself.

        Then each thread owns its elements, and so their gradients: the adjoint may
        accumulate without atomics. (Passing one array as two parameters breaks this,
        as it breaks the forward kernel's own assumptions.)
        """
        hit = self._owned.get(arr)
        if hit is None:
            nd = arr.type.ndim
            hit = True
            for op, index in arr.uses:
                if op.name not in ("kd.load", "kd.store", "kd.atomic_rmw"):
                    continue
                first = 1 if op.name == "kd.load" else 2
                idx = op.operands[first : first + nd]
                if index != first - 1 or not all(_is_tid(v, d, nd) for d, v in enumerate(idx)):
                    hit = False
                    break
            self._owned[arr] = hit
        return hit

    def _callee(self, call: Operation) -> Operation:
        return self.module.get_func(call.attrs["callee"])

    def _reverse_call(self, op: Operation, vmap, adj) -> None:
        """A call to a function with a custom gradient (``@kdsl.func_grad``).

        The gradient function takes the primal arguments and one adjoint per result,
        and returns one adjoint contribution per argument.
        """
        seeds = [adj.get(r) for r in op.results]
        if all(s is None for s in seeds):
            return
        grad = self.module.get_func(self._callee(op).attrs["custom_grad"])
        args = [vmap[v] for v in op.operands]
        args += [s or self._zeros(r.type) for s, r in zip(seeds, op.results)]
        call = self.b.create("func.call", args, [v.type for v in op.operands],
                             {"callee": grad.attrs["sym_name"]})  # fmt: skip
        for operand, c in zip(op.operands, call.results):
            self._acc(adj, operand, c)

    def _reverse_write(self, op: Operation, vmap, adj) -> None:
        v, arr = op.operands[0], op.operands[1]
        grad = self.adj_arrays.get(arr)
        if grad is None or not is_differentiable(v.type):
            return
        b = self.b
        idx = [vmap[i] for i in op.operands[2:]]
        g = b.value("kd.load", grad, *idx)
        kind = op.attrs.get("kind", "store")
        if kind == "sub":
            g = b.value("arith.neg", g)
        elif kind in ("min", "max"):
            # The value reached the array only if it is what the array holds now.
            now = b.value("kd.load", vmap[arr], *idx)
            g = b.value("arith.select", b.value("arith.cmp", now, vmap[v], pred="eq"), g,
                        self._zeros(v.type))  # fmt: skip
        elif kind in ("store", "exch") and arr in self.fblock.args:
            self._consume(grad, idx, self.fblock.args.index(arr), v.type)
        self._acc(adj, v, g)

    def _consume(self, grad: Value, idx: list[Value], param: int, t: Type) -> None:
        """Zero ``grad[idx]`` after a store's adjoint read it, if the runtime says so.

        A store overwrites the element, so the gradient of its old value is zero: the
        element's adjoint must be consumed for in-place updates to differentiate right.
        The runtime sets bit ``param`` of the hidden ``grad_owned`` mask when the
        gradient array is the array's own ``.grad`` (as Warp does); gradient buffers a
        caller passes explicitly are left as they were.
        """
        b = self.b
        if not hasattr(self, "grad_owned"):
            self.grad_owned = self.body.add_arg(I64, "grad_owned")
        bit = b.value("arith.and", b.value("arith.shr", self.grad_owned, b.constant(param, I64)),
                      b.constant(1, I64))  # fmt: skip
        owned = b.value("arith.cmp", bit, b.constant(0, I64), pred="ne")
        then, other = Block(), Block()
        with b.at_end(then):
            b.create("kd.store", [self._zeros(t), grad, *idx])
            b.create("scf.yield", [])
        with b.at_end(other):
            b.create("scf.yield", [])
        b.create("scf.if", [owned], [], regions=[Region(then), Region(other)])

    def _reverse_if(self, op: Operation, vmap, adj) -> None:
        b = self.b
        inside = _defined_in(op)
        branches: list[tuple[Block, dict[Value, Value]]] = []
        for region in op.regions:
            blk = Block()
            inner = dict(vmap)
            a = dict(adj)
            with b.at_end(blk):
                self.replay(region.block, inner, record=True)
                for x, res in zip(region.block.terminator.operands, op.results):
                    self._acc(a, x, adj.get(res))
                self.reverse_block(region.block, inner, a)
            branches.append((blk, a))
        changed: dict[Value, None] = {}
        for _, a in branches:
            for k, v in a.items():
                if k not in inside and adj.get(k) is not v:
                    changed.setdefault(k, None)
        for blk, a in branches:
            with b.at_end(blk):
                outs = [a.get(k) or self._zeros(k.type) for k in changed]
                b.create("scf.yield", outs)
        new = b.create("scf.if", [vmap[op.operands[0]]], [k.type for k in changed],
                       regions=[Region(branches[0][0]), Region(branches[1][0])])  # fmt: skip
        for k, r in zip(changed, new.results):
            adj[k] = r

    def _reverse_loop(self, op, vmap, adj, seeds, outer, body_fn) -> list[Value]:
        """A reversed counted loop over the taped iterations; gives the final adjoints.

        ``seeds`` are the adjoints carried in (one per differentiable carried value),
        ``outer`` the outer values whose adjoints the body may add to; ``body_fn(k,
        carried_adj, outer_adj)`` emits one reversed iteration and returns the next
        carried adjoints and the outer ones.
        """
        b = self.b
        n = self.trips[op]
        zero, one = b.constant(0, I32), b.constant(1, I32)
        init = [*seeds, *[adj.get(o) or self._zeros(o.type) for o in outer]]
        blk = Block([I32] + [v.type for v in init])
        with b.at_end(blk):
            t = blk.args[0]
            k = b.value("arith.sub", b.value("arith.sub", n, one), t)
            carried = blk.args[1 : 1 + len(seeds)]
            outer_adj = blk.args[1 + len(seeds) :]
            nxt, nxt_outer = body_fn(k, list(carried), list(outer_adj))
            b.create("scf.yield", [*nxt, *nxt_outer])
        new = b.create("scf.for", [zero, n, one, *init], [v.type for v in init],
                       regions=[Region(blk)])  # fmt: skip
        res = list(new.results)
        for o, r in zip(outer, res[len(seeds) :]):
            adj[o] = r
        return res[: len(seeds)]

    def _reverse_for(self, op: Operation, vmap, adj) -> None:
        b = self.b
        tape = self.tape_of[op]
        body = op.regions[0].block
        carried = body.args[1:]
        nexts = body.terminator.operands
        diff = [j for j, a in enumerate(carried) if is_differentiable(a.type)]
        outer = _outer_uses(op)
        seeds = [adj.get(op.results[j]) or self._zeros(carried[j].type) for j in diff]

        def one_iteration(k, carried_adj, outer_adj):
            xs = self._load_tape(tape, k, [a.type for a in carried])
            lb, step = vmap[op.operands[0]], vmap[op.operands[2]]
            kk = k if lb.type == I32 else b.create("arith.cast", [k], [lb.type]).result
            iv = b.value("arith.add", lb, b.value("arith.mul", kk, step))
            inner = dict(vmap)
            inner[body.args[0]] = iv
            inner.update(zip(carried, xs))
            self.replay(body, inner, record=True)
            a = dict(zip(outer, outer_adj))
            for j, g in zip(diff, carried_adj):
                self._acc(a, nexts[j], g)
            self.reverse_block(body, inner, a)
            return ([a.get(carried[j]) or self._zeros(carried[j].type) for j in diff],
                    [a[o] for o in outer])  # fmt: skip

        final = self._reverse_loop(op, vmap, adj, seeds, outer, one_iteration)
        for j, g in zip(diff, final):
            self._acc(adj, op.operands[3 + j], g)

    def _reverse_while(self, op: Operation, vmap, adj) -> None:
        tape = self.tape_of[op]
        before, after = op.regions[0].block, op.regions[1].block
        passed = before.terminator.operands[1:]
        nexts = after.terminator.operands
        xtypes = [a.type for a in before.args]
        diff_x = [i for i, a in enumerate(before.args) if is_differentiable(a.type)]
        diff_v = [i for i, a in enumerate(after.args) if is_differentiable(a.type)]

        # The last run of the before region (slot N) produced the loop's results.
        n = self.trips[op]
        inner = dict(vmap)
        inner.update(zip(before.args, self._load_tape(tape, n, xtypes)))
        self.replay(before, inner, record=True)
        last = dict(adj)
        for i in diff_v:
            self._acc(last, passed[i], adj.get(op.results[i]))
        self.reverse_block(before, inner, last)
        outside = _defined_in(op)
        for k, v in last.items():
            if k not in outside:
                adj[k] = v
        seeds = [last.get(before.args[i]) or self._zeros(xtypes[i]) for i in diff_x]
        outer = _outer_uses(op)

        def one_iteration(k, carried_adj, outer_adj):
            inner = dict(vmap)
            inner.update(zip(before.args, self._load_tape(tape, k, xtypes)))
            outs = self.replay(before, inner, record=True)
            inner.update(zip(after.args, outs[1:]))
            self.replay(after, inner, record=True)
            a = dict(zip(outer, outer_adj))
            for i, g in zip(diff_x, carried_adj):
                self._acc(a, nexts[i], g)
            self.reverse_block(after, inner, a)
            for i in diff_v:
                self._acc(a, passed[i], a.get(after.args[i]))
            self.reverse_block(before, inner, a)
            return ([a.get(before.args[i]) or self._zeros(xtypes[i]) for i in diff_x],
                    [a[o] for o in outer])  # fmt: skip

        final = self._reverse_loop(op, vmap, adj, seeds, outer, one_iteration)
        for i, g in zip(diff_x, final):
            self._acc(adj, op.operands[i], g)

