"""IR module -> LLVM IR module (text through ``llvmlite.ir``).

Every kernel becomes ``void NAME(i64 start, i64 end, ptr args, ptr dims)``: it runs
the threads with linear index in ``[start, end)``. ``args[k]`` points at the k-th
argument: an array descriptor, a scalar or vector in its memory layout, or, for a
struct, an array of pointers to its fields (in the same scheme). ``dims`` holds the
launch grid (i64 per dimension), used to split the linear index when the kernel
asks for an n-d ``tid``. Parameters are loaded once before the thread loop, so the
loop body sees loop-invariant values and simple kernels vectorize.

Debug builds (``lower_kernels(..., debug=True)``) read one more entry,
``args[nparams]``: the error record of ``checks``; internal functions then take
it as an extra last parameter.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from llvmlite import ir

from kdsl.backends.cpu import lane_blocks, loop_md
from kdsl.backends.cpu import types as LT
from kdsl.backends.cpu.composite import Parts, leaf_types, leaves, rebuild_all
from kdsl.backends.cpu.emitter import Emitter, ModuleState
from kdsl.backends.cpu.interior import inside, interior_box, split_range
from kdsl.backends.cpu.kernel_facts import kernel_symbol, tid_ndims
from kdsl.backends.cpu.local_sums import LocalSums, find_sites
from kdsl.backends.cpu.memory import load_value
from kdsl.backends.cpu.ops import TABLE
from kdsl.backends.cpu.versioning import vector_arrays, versioned
from kdsl.errors import KdslCapabilityError
from kdsl.ir import types as T
from kdsl.ir.core import Block, Module, Operation
from kdsl.passes.thread_interior import InteriorPlan, interior_plan

KERNEL_TYPE = ir.FunctionType(LT.VOID, [LT.I64, LT.I64, LT.PTR, LT.PTR])


def new_module(module: Module, name: str = "kdsl") -> ModuleState:
    """An empty LLVM module with the lowering state for IR ``module``."""
    return ModuleState(ir.Module(name=name), module, TABLE)


def _load_param(em: Emitter, ptr: ir.Value, t: T.Type) -> Any:
    """Load a kernel parameter of type ``t`` from ``ptr`` (vectors and structs as ``Parts``)."""
    B = em.b
    if isinstance(t, T.ArrayType):
        return B.load(ptr, typ=LT.descriptor_type(t.ndim), align=8)
    if isinstance(t, T.StructType):
        fields = []
        for i, (_, ft) in enumerate(t.fields):
            slot = B.gep(ptr, [ir.Constant(LT.I64, i)], inbounds=True, source_etype=LT.PTR)
            fields.append(_load_param(em, B.load(slot, typ=LT.PTR, align=8), ft))
        return Parts(fields)
    if isinstance(t, T.HandleType):
        return B.load(ptr, typ=LT.I64, align=8)
    return load_value(em, ptr, t)


def emit_kernel(state: ModuleState, func: Operation, llname: str) -> ir.Function:
    """Emit the range function of kernel ``func`` into ``state``'s module."""
    fn = ir.Function(state.llmod, KERNEL_TYPE, llname)
    fn.attributes.add("nounwind")
    start, end, args, dims = fn.args
    em = Emitter(state, fn, func.attrs["sym_name"])
    if not state.debug:  # the thread loop's array accesses are independent (loop_md)
        em.access_group = loop_md.access_group(state.llmod)
        em.kernel_arrays = loop_md.kernel_arrays(func)
        em.unroll_inside = loop_md.thread_parallel(func)
    B = em.b
    entry = fn.append_basic_block("entry")
    B.position_at_end(entry)
    body_block = func.regions[0].block
    params = []
    for k, a in enumerate(body_block.args):
        slot = B.gep(args, [ir.Constant(LT.I64, k)], inbounds=True, source_etype=LT.PTR)
        params.append(_load_param(em, B.load(slot, typ=LT.PTR, align=8), a.type))
    if state.debug:
        slot = B.gep(args, [ir.Constant(LT.I64, len(params))], inbounds=True, source_etype=LT.PTR)
        em.error_record = B.load(slot, typ=LT.PTR, align=8)
    nds = sorted(n for n in tid_ndims(func) if n > 1)
    if len(nds) > 1:
        raise KdslCapabilityError(f"kernel uses tid() with {nds} dimensions at once", func.loc)
    extents = []
    for d in range(nds[0] if nds else 0):
        p = B.gep(dims, [ir.Constant(LT.I64, d)], inbounds=True, source_etype=LT.I64)
        extents.append(B.load(p, typ=LT.I64, align=8))
    em.bind(body_block.args, params)

    # Bounds tests on the thread index: the interior runs a copy without them.
    plan = None if state.debug else interior_plan(state.module, func)
    if not state.debug:  # atomic adds to one element: summed per range, one atomic after
        sites = find_sites(body_block)
        if plan is not None:
            sites += find_sites(plan.interior.regions[0].block)
        em.local_sums = LocalSums(B, sites) if sites else None

    # A thread loop around one uniform loop runs in blocks of threads (``lane_blocks``).
    lanes = None if state.debug or extents or plan else lane_blocks.lane_plan(func)

    def emit() -> list:
        # Parameters are read back from the value map: ``versioned`` rebinds dense arrays.
        now = [em.get(a) for a in body_block.args]
        if extents:
            _row_loops(em, body_block, now, start, end, extents, plan)
        else:
            _flat_loop(em, body_block, now, start, end, plan, lanes)
        return []

    # Threads over arrays of vectors vectorize only with constant strides: see
    # ``versioning``. A body with loops of its own is not copied (they are versioned).
    has_loops = any(op.name in ("scf.for", "scf.while")
                    and not (em.unroll_inside and loop_md.short_trips(op))
                    for op in func.walk())  # fmt: skip
    arrays = [] if has_loops else vector_arrays(body_block.args)
    if arrays:
        versioned(em, arrays, emit, [])
    else:
        emit()
    if em.local_sums is not None:
        em.local_sums.flush(B, fn)
    B.ret_void()
    return fn


def _count_head(
    B: ir.IRBuilder,
    name: str,
    lo: ir.Value,
    hi: ir.Value,
    entry: ir.Block,
    head: ir.Block,
    body: ir.Block,
    exit_: ir.Block,
) -> ir.Value:
    """The head of an i32 loop counting from ``lo`` (entered from ``entry``) while ``< hi``.

    The builder is left in ``body``; the counter, a phi named ``name``, is returned for the
    caller to add its latch's value.
    """
    B.branch(head)
    B.position_at_end(head)
    i = B.phi(LT.I32, name=name)
    i.add_incoming(lo, entry)
    B.cbranch(B.icmp_signed("<", i, hi), body, exit_)
    B.position_at_end(body)
    return i


def _flat_loop(
    em: Emitter,
    body: Block,
    params: list,
    start: ir.Value,
    end: ir.Value,
    plan: InteriorPlan | None = None,
    lanes: lane_blocks.LanePlan | None = None,
) -> None:
    """The thread loop of a kernel with a 1-d index: counted loops over ``[start, end)``.

    With a ``plan`` the range is split into edges and interior (see ``_peeled``); with
    ``lanes`` it runs in blocks of threads (``lane_blocks``), the rest in the plain loop.
    Like ``_row_loops`` it leaves the builder in its exit block.
    """
    B = em.b

    def at(i: ir.Value) -> None:
        em.linear = i
        em.index = []

    def span(lo: ir.Value, hi: ir.Value) -> None:
        _span(em, body, params, lo, hi, at, "thread")

    # The loops count in i32 (tid is i32) with no-wrap adds, so LLVM sees a simple
    # induction variable; launches are limited to 2**31 threads.
    if plan is None:
        lo, hi = B.trunc(start, LT.I32), B.trunc(end, LT.I32)
        if lanes is None:
            span(lo, hi)
        else:
            lane_blocks.emit(em, lanes, lo, hi, span)
        return
    lo, hi = interior_box(em, plan, [end])
    a, b = split_range(em, start, end, lo[0], hi[0])
    _peeled(em, body, plan, params, [start, a, b, end], at, "thread")


def _peeled(
    em: Emitter,
    body: Block,
    plan: InteriorPlan,
    params: list,
    marks: list[ir.Value],
    at: Callable[[ir.Value], None],
    name: str,
) -> None:
    """The edges ``[m0, m1)`` and ``[m2, m3)`` in one loop (one copy of the body: it
    jumps from ``m1`` to ``m2``), then the interior ``[m1, m2)``; marks are i64."""
    B = em.b
    m = [B.trunc(x, LT.I32) for x in marks]

    def skip(nxt: ir.Value) -> ir.Value:
        return B.select(B.icmp_signed("==", nxt, m[1]), m[2], nxt)

    start = B.select(B.icmp_signed("==", m[0], m[1]), m[2], m[0])
    _span(em, body, params, start, m[3], at, name + ".edge", skip)
    _span(em, plan.interior.regions[0].block, params, m[1], m[2], at, name + ".inner")


def _span(
    em: Emitter,
    body: Block,
    params: list,
    lo: ir.Value,
    hi: ir.Value,
    at: Callable[[ir.Value], None],
    name: str,
    skip: Callable[[ir.Value], ir.Value] | None = None,
) -> None:
    """One i32 loop from ``lo`` while ``< hi`` running ``body``; ``at(i)`` sets the index.

    ``skip`` maps each next index to the one to run (the edge loop of ``_peeled``). The
    builder is left in the loop's exit block.
    """
    B, fn = em.b, em.fn
    entry = B.block
    head, body_bb, done = (fn.append_basic_block(f"{name}.{n}") for n in ("head", "body", "exit"))
    i = _count_head(
        B, "tid" if name == "thread" else f"tid.{name}", lo, hi, entry, head, body_bb, done
    )
    at(i)
    _thread_body(em, body, params, i, head, skip)
    B.position_at_end(done)


def _row_loops(
    em: Emitter,
    body: Block,
    params: list,
    start: ir.Value,
    end: ir.Value,
    extents: list,
    plan: InteriorPlan | None = None,
) -> None:
    """The thread loop of a kernel with an n-d index: rows of the last dimension.

    The linear range ``[start, end)`` is walked one row at a time: the outer
    components are split from the row number once per row, and the inner loop
    counts the last component directly. So a stencil's inner loop is a plain
    counted loop with no division per thread, which LLVM can vectorize. With a
    ``plan`` (bounds tests on the thread index) a row inside the interior box runs
    its edge columns in one loop and its interior columns (the folded body) in another.
    """
    B, fn = em.b, em.fn
    box = interior_box(em, plan, extents) if plan is not None else None
    entry = B.block
    inner = extents[-1]
    row0, col0 = B.udiv(start, inner), B.urem(start, inner)
    names = ("row.head", "row.body", "row.next", "exit")
    row_head, row_body, row_next, done = (fn.append_basic_block(n) for n in names)
    B.branch(row_head)
    B.position_at_end(row_head)
    row = B.phi(LT.I64, name="row")
    first = B.phi(LT.I64, name="col.first")
    row.add_incoming(row0, entry)
    first.add_incoming(col0, entry)
    row_base = B.mul(row, inner, flags=["nuw", "nsw"])
    B.cbranch(B.icmp_signed("<", B.add(row_base, first), end), row_body, done)
    B.position_at_end(row_body)
    left = B.sub(end, row_base)
    last = B.select(B.icmp_signed("<", left, inner), left, inner)
    outer = _split_index(em, row, extents[:-1])
    base32 = B.trunc(row_base, LT.I32)

    def at(col: ir.Value) -> None:
        em.linear = B.add(base32, col, flags=["nsw"])
        em.index = [*outer, col]

    if box is None or plan is None:
        _span(em, body, params, B.trunc(first, LT.I32), B.trunc(last, LT.I32), at, "col")
    else:
        lo, hi = box
        lo_col = lo[-1]
        for d, t in enumerate(outer):  # a row outside the box runs as edge only
            if d in plan.dims():
                lo_col = B.select(inside(em, lo[d], hi[d], t), lo_col, last)
        a, b = split_range(em, first, last, lo_col, hi[-1])
        _peeled(em, body, plan, params, [first, a, b, last], at, "col")
    B.branch(row_next)
    B.position_at_end(row_next)
    row.add_incoming(B.add(row, ir.Constant(LT.I64, 1), flags=["nuw", "nsw"]), row_next)
    first.add_incoming(ir.Constant(LT.I64, 0), row_next)
    B.branch(row_head)
    B.position_at_end(done)


def _thread_body(
    em: Emitter,
    body: Block,
    params: list,
    counter: ir.PhiInstr,
    head: ir.Block,
    skip: Callable[[ir.Value], ir.Value] | None = None,
) -> None:
    """One thread's code, then the step of ``counter`` (``skip``-ped when given) and the
    branch back to ``head``."""
    B, fn = em.b, em.fn

    def step() -> ir.Value:
        nxt = B.add(counter, ir.Constant(LT.I32, 1), flags=["nsw"])
        return nxt if skip is None else skip(nxt)

    if em.state.debug:  # a failed check ends its thread by branching here
        em.abort_block = fn.append_basic_block("thread.abort")
    em.lower_block(body, params)
    counter.add_incoming(step(), B.block)
    latch = B.branch(head)
    if em.access_group is not None:  # its threads' array accesses are independent
        latch.set_metadata("llvm.loop", loop_md.parallel_loop(em.state.llmod, em.access_group))
    if em.abort_block is not None:
        B.position_at_end(em.abort_block)
        counter.add_incoming(step(), em.abort_block)
        B.branch(head)


def _split_index(em: Emitter, linear: ir.Value, extents: list[ir.Value]) -> list[ir.Value]:
    """Row-major n-d index components (i32) of an i64 linear index over ``extents``."""
    if not extents:
        return []
    B = em.b
    rest = linear
    out = []
    for ext in reversed(extents[1:]):
        out.append(B.trunc(B.urem(rest, ext), LT.I32))
        rest = B.udiv(rest, ext)
    out.append(B.trunc(rest, LT.I32))
    return out[::-1]


def declare_func(state: ModuleState, name: str) -> ir.Function:
    """The internal LLVM function of IR function ``name``, emitted on first use."""
    fn = state.funcs.get(name)
    if fn is not None:
        return fn
    if not state.module.has_func(name):
        raise KdslCapabilityError(f"call to unknown function '{name}'")
    func = state.module.get_func(name)
    body = func.regions[0].block
    # Vector, matrix and struct values cross the call as their leaves (``composite``).
    res = [lt for t in func.attrs.get("res_types", []) for lt in leaf_types(t)]
    ret = LT.VOID if not res else res[0] if len(res) == 1 else ir.LiteralStructType(res)
    params = [lt for a in body.args for lt in leaf_types(a.type)]
    fnty = ir.FunctionType(ret, params + [LT.PTR] if state.debug else params)
    fn = ir.Function(state.llmod, fnty, f"kdsl_func_{name}")
    fn.linkage = "internal"
    state.funcs[name] = fn
    em = Emitter(state, fn, name)
    em.b.position_at_end(fn.append_basic_block("entry"))
    if state.debug:
        em.error_record = fn.args[-1]
    args = rebuild_all([a.type for a in body.args], list(fn.args)[: len(params)])
    out = [leaf for v in em.lower_block(body, args) for leaf in leaves(v)]
    if not res:
        em.b.ret_void()
    elif len(res) == 1:
        em.b.ret(out[0])
    else:
        agg = ir.Constant(ret, ir.Undefined)
        for i, v in enumerate(out):
            agg = em.b.insert_value(agg, v, i)
        em.b.ret(agg)
    return fn


def lower_kernels(
    module: Module,
    kernels: list[str],
    names: dict[str, str] | None = None,
    debug: bool = False,
    fast_math: bool = False,
) -> ModuleState:
    """An LLVM module holding the range functions of ``kernels`` (and their callees).

    ``names`` maps a kernel symbol to its LLVM name (default ``kernel_symbol``).
    ``debug`` builds take an error record (``checks``) and can lower the check ops.
    ``fast_math`` puts ``emitter.FAST_MATH_FLAGS`` on every float op of every function.
    """
    state = new_module(module)
    state.debug = debug
    state.fast_math = fast_math
    for k in kernels:
        func = module.get_func(k)
        emit_kernel(state, func, (names or {}).get(k) or kernel_symbol(k))
    return state
