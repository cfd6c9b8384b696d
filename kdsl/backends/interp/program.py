"""Compile IR functions into trees of Python closures, and run them.

Each SSA value gets a slot in a per-call frame (a list). Each op becomes one
closure that reads its operand slots, calls the op catalog's ``interp`` rule and
writes its result slots, so running a thread does no lookups by op name. Ops
that need nothing from the running thread (constants) are evaluated once, at
compile time, through the same catalog rule.

The interpreter's lowering of an op is its catalog ``interp`` rule: that is this
backend's default in the lowering registry (``kdsl.ir.lowering``), so the
registry reports it and an explicit ``interp`` registration would override it.
Terminators and ``func.func`` are structural: a block's terminator gives the
values it yields (``CompiledBlock.term_slots``), a function is compiled whole.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from kdsl.backends.base import Args, Dims, check_tid_ndims, split_block
from kdsl.errors import KdslCapabilityError, KdslError, KdslRuntimeError
from kdsl.ir.core import Block, Module, Operation, Region, Value
from kdsl.ir.lowering import LOWERINGS

Step = Callable[["ThreadContext", list], None]

INTERP = LOWERINGS.for_backend("interp")
LOWERINGS.set_default("interp", lambda opdef: opdef.interp, "the op's catalog interp rule")
INTERP.structural("func.func", "compiled whole by `Program.function`")


@dataclass(slots=True, eq=False)
class CompiledBlock:
    """A block as closures: where its arguments go, its steps, what it yields."""

    arg_slots: list[int]
    steps: list[Step]
    term_slots: list[int]


@dataclass(eq=False)
class CompiledFunction:
    """One ``func.func``: its entry block, its nested regions and a frame template."""

    name: str
    template: list
    entry: CompiledBlock
    regions: dict[Region, CompiledBlock]
    tid_ndims: set[int]


class _NotConstant(Exception):
    """Raised by the compile-time context when a rule needs the running thread."""


class _ConstContext:
    kernel_name = "?"

    def tid(self, dim: int, ndim: int) -> Any:
        raise _NotConstant

    def run_region(self, region: Region, args: Sequence[Any]) -> list:
        raise _NotConstant

    def call(self, callee: str, args: Sequence[Any]) -> list:
        raise _NotConstant


class _FunctionCompiler:
    def __init__(self, func: Operation) -> None:
        self.func = func
        self.slots: dict[Value, int] = {}
        self.template: list = []
        self.regions: dict[Region, CompiledBlock] = {}
        self.tid_ndims: set[int] = set()

    def slot(self, v: Value) -> int:
        s = self.slots.get(v)
        if s is None:
            s = self.slots[v] = len(self.template)
            self.template.append(None)
        return s

    def compile(self) -> CompiledFunction:
        entry = self.block(self.func.regions[0].block)
        name = self.func.attrs["sym_name"]
        return CompiledFunction(name, self.template, entry, self.regions, self.tid_ndims)

    def block(self, block: Block) -> CompiledBlock:
        arg_slots = [self.slot(a) for a in block.args]
        ops, yielded = split_block(block)
        steps = [step for step in map(self.op, ops) if step is not None]
        return CompiledBlock(arg_slots, steps, [self.slot(v) for v in yielded])

    def op(self, op: Operation) -> Step | None:
        rule = LOWERINGS.get(op.opdef, "interp")
        if rule is None:
            raise KdslCapabilityError(f"the interp backend has no rule for {op.name}", op.loc)
        if op.name == "kd.tid":
            self.tid_ndims.add(op.attrs["ndim"])
        for region in op.regions:
            self.regions[region] = self.block(region.block)
        ins = [self.slot(v) for v in op.operands]
        outs = [self.slot(r) for r in op.results]
        if not ins and not op.regions and op.opdef.is_pure and len(outs) == 1:
            try:
                self.template[outs[0]] = rule(_ConstContext(), op)
                return None
            except _NotConstant:
                pass
        return _make_step(op, rule, ins, outs)


def _make_step(op: Operation, rule: Callable, ins: list[int], outs: list[int]) -> Step:
    """One closure per op, specialized on arity so the common cases stay cheap."""
    n_in = len(ins)
    if len(outs) == 1:
        o = outs[0]
        if n_in == 0:

            def run(ctx, f):
                f[o] = rule(ctx, op)
        elif n_in == 1:
            a = ins[0]

            def run(ctx, f):
                f[o] = rule(ctx, op, f[a])
        elif n_in == 2:
            a, b = ins

            def run(ctx, f):
                f[o] = rule(ctx, op, f[a], f[b])
        else:

            def run(ctx, f):
                f[o] = rule(ctx, op, *[f[i] for i in ins])
    elif not outs:

        def run(ctx, f):
            rule(ctx, op, *[f[i] for i in ins])
    else:

        def run(ctx, f):
            for s, v in zip(outs, rule(ctx, op, *[f[i] for i in ins])):
                f[s] = v

    def step(ctx, f):
        try:
            run(ctx, f)
        except KdslError:
            raise
        except Exception as e:
            raise KdslRuntimeError(
                f"the interp backend failed on {op.name}: {type(e).__name__}: {e}",
                op.loc,
                ctx.kernel_name,
            ) from e

    return step


class Program:
    """All functions of a module, compiled on first use."""

    def __init__(self, module: Module) -> None:
        self.module = module
        self.funcs: dict[str, CompiledFunction] = {}

    def function(self, name: str) -> CompiledFunction:
        fn = self.funcs.get(name)
        if fn is None:
            if not self.module.has_func(name):
                raise KdslRuntimeError(f"call to unknown function '{name}'")
            fn = self.funcs[name] = _FunctionCompiler(self.module.get_func(name)).compile()
        return fn


class ThreadContext:
    """The ``ctx`` the catalog's interp rules receive: thread index, regions, calls."""

    def __init__(self, program: Program, fn: CompiledFunction, kernel_name: str) -> None:
        self.program = program
        self.kernel_name = kernel_name
        self.fn = fn
        self.frame: list = list(fn.template)
        self.linear = np.int32(0)
        self.index: tuple = (np.int32(0),)

    def tid(self, dim: int, ndim: int) -> np.int32:
        """The linear index (ndim 1) or component ``dim`` of the n-d index."""
        if ndim == 1:
            return self.linear
        return self.index[dim]

    def run_region(self, region: Region, args: Sequence[Any]) -> list:
        """Run a region of the current function; gives its terminator's operands."""
        return _run_block(self, self.fn.regions[region], args)

    def call(self, callee: str, args: Sequence[Any]) -> list:
        """Call a function of the module in a fresh frame; gives its results."""
        fn = self.program.function(callee)
        saved_fn, saved_frame = self.fn, self.frame
        self.fn, self.frame = fn, list(fn.template)
        try:
            return _run_block(self, fn.entry, args)
        finally:
            self.fn, self.frame = saved_fn, saved_frame


def _run_block(ctx: ThreadContext, blk: CompiledBlock, args: Sequence[Any]) -> list:
    f = ctx.frame
    for s, v in zip(blk.arg_slots, args):
        f[s] = v
    for step in blk.steps:
        step(ctx, f)
    return [f[s] for s in blk.term_slots]


def run_kernel(
    program: Program, symbol: str, dims: Dims, args: Args, name: str | None = None
) -> None:
    """Run kernel ``symbol`` once per thread of ``dims``, in row-major order.

    ``name`` is the kernel's name as the user wrote it, for error messages.
    """
    fn = program.function(symbol)
    name = name or symbol
    check_tid_ndims(name, dims, fn.tid_ndims)
    ctx = ThreadContext(program, fn, name)
    f = ctx.frame
    entry = fn.entry
    for s, v in zip(entry.arg_slots, args):
        f[s] = v
    steps = entry.steps
    i32 = np.int32
    with np.errstate(all="ignore"):
        for linear, idx in enumerate(itertools.product(*(range(d) for d in dims))):
            ctx.linear = i32(linear)
            ctx.index = tuple(i32(i) for i in idx)
            try:
                for step in steps:
                    step(ctx, f)
            except KdslError as e:
                where = idx[0] if len(idx) == 1 else idx
                raise e.add_context(f"in thread {where} of kernel '{name}'") from None
