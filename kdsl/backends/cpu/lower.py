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

from llvmlite import ir

from kdsl.backends.cpu import types as LT
from kdsl.backends.cpu.emitter import Emitter, ModuleState
from kdsl.backends.cpu.memory import load_value
from kdsl.backends.cpu.ops import TABLE
from kdsl.errors import KdslCapabilityError
from kdsl.ir import types as T
from kdsl.ir.core import Module, Operation

KERNEL_TYPE = ir.FunctionType(LT.VOID, [LT.I64, LT.I64, LT.PTR, LT.PTR])


def kernel_symbol(name: str) -> str:
    """The LLVM name of the range function of kernel ``name``."""
    return f"kdsl_kernel_{name}"


def tid_ndims(func: Operation) -> set[int]:
    """The ``ndim`` of every ``kd.tid`` in ``func``."""
    return {op.attrs["ndim"] for op in func.walk() if op.name == "kd.tid"}


def new_module(module: Module, name: str = "kdsl") -> ModuleState:
    """An empty LLVM module with the lowering state for IR ``module``."""
    return ModuleState(ir.Module(name=name), module, TABLE)


def _load_param(em: Emitter, ptr: ir.Value, t: T.Type) -> ir.Value:
    B = em.b
    if isinstance(t, T.ArrayType):
        if isinstance(t.dtype, T.StructType):
            raise KdslCapabilityError(f"arrays of {t.dtype} are not supported by the cpu backend")
        return B.load(ptr, typ=LT.descriptor_type(t.ndim), align=8)
    if isinstance(t, T.StructType):
        out = ir.Constant(LT.llvm_type(t), ir.Undefined)
        for i, (_, ft) in enumerate(t.fields):
            slot = B.gep(ptr, [ir.Constant(LT.I64, i)], inbounds=True, source_etype=LT.PTR)
            field = _load_param(em, B.load(slot, typ=LT.PTR, align=8), ft)
            out = B.insert_value(out, field, i)
        return out
    if isinstance(t, T.HandleType):
        return B.load(ptr, typ=LT.I64, align=8)
    return load_value(em, ptr, t)


def emit_kernel(state: ModuleState, func: Operation, llname: str) -> ir.Function:
    """Emit the range function of kernel ``func`` into ``state``'s module."""
    fn = ir.Function(state.llmod, KERNEL_TYPE, llname)
    fn.attributes.add("nounwind")
    start, end, args, dims = fn.args
    em = Emitter(state, fn, func.attrs["sym_name"])
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
    # The loop counts in i32 (tid is i32) with no-wrap adds, so LLVM sees a simple
    # induction variable; launches are limited to 2**31 threads.
    lo, hi = B.trunc(start, LT.I32), B.trunc(end, LT.I32)
    head, body, done = (fn.append_basic_block(n) for n in ("thread.head", "thread.body", "exit"))
    B.branch(head)
    B.position_at_end(head)
    i = B.phi(LT.I32, name="tid")
    i.add_incoming(lo, entry)
    B.cbranch(B.icmp_signed("<", i, hi), body, done)
    B.position_at_end(body)
    em.linear = i
    em.index = _split_index(em, i, extents)
    if state.debug:  # a failed check ends its thread by branching here
        em.abort_block = fn.append_basic_block("thread.abort")
    em.lower_block(body_block, params)
    i.add_incoming(B.add(i, ir.Constant(LT.I32, 1), flags=["nsw"]), B.block)
    B.branch(head)
    if em.abort_block is not None:
        B.position_at_end(em.abort_block)
        i.add_incoming(B.add(i, ir.Constant(LT.I32, 1), flags=["nsw"]), em.abort_block)
        B.branch(head)
    B.position_at_end(done)
    B.ret_void()
    return fn


def _split_index(em: Emitter, linear: ir.Value, extents: list[ir.Value]) -> list[ir.Value]:
    """Row-major n-d index components (i32) of a linear thread index."""
    if not extents:
        return []
    B = em.b
    rest = B.zext(linear, LT.I64)
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
    res = [LT.llvm_type(t) for t in func.attrs.get("res_types", [])]
    ret = LT.VOID if not res else res[0] if len(res) == 1 else ir.LiteralStructType(res)
    params = [LT.llvm_type(a.type) for a in body.args]
    fnty = ir.FunctionType(ret, params + [LT.PTR] if state.debug else params)
    fn = ir.Function(state.llmod, fnty, f"kdsl_func_{name}")
    fn.linkage = "internal"
    state.funcs[name] = fn
    em = Emitter(state, fn, name)
    em.b.position_at_end(fn.append_basic_block("entry"))
    if state.debug:
        em.error_record = fn.args[-1]
    out = em.lower_block(body, list(fn.args)[: len(params)])
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


def kernel_names(module: Module) -> list[str]:
    """Symbols of the kernels of ``module``."""
    return [f.attrs["sym_name"] for f in module.funcs if f.attrs.get("kind") == "kernel"]
