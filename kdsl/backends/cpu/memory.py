"""Lowerings of the ``kd`` dialect: thread index, array shape, load, store, atomics.

An array value is its descriptor struct (see ``types``). Element addresses are
``data + sum(i_k * stride_k)`` in scalar elements. Indices are NOT bounds-checked:
an out-of-range index reads or writes wild memory. Use the ``interp`` backend
(which always checks) to find such bugs.
"""

from __future__ import annotations

from typing import Any

from llvmlite import ir

from kdsl.backends.cpu import types as LT
from kdsl.backends.cpu.composite import Parts, components
from kdsl.backends.cpu.emitter import Emitter
from kdsl.backends.cpu.loop_md import mark_access
from kdsl.errors import KdslCapabilityError
from kdsl.ir import types as T
from kdsl.ir.core import Operation, Value
from kdsl.ir.lowering import LOWERINGS
from kdsl.ir.records import element_strides, record_dtype

CPU = LOWERINGS.for_backend("cpu")


def _tid(em: Emitter, op: Operation) -> ir.Value:
    dim, ndim = op.attrs["dim"], op.attrs["ndim"]
    if em.linear is None:
        raise KdslCapabilityError("tid() is only available inside a kernel on cpu", op.loc)
    if ndim == 1:
        return em.linear
    return em.index[dim]


def _array_shape(em: Emitter, op: Operation) -> ir.Value:
    (a,) = em.args(op)
    n = em.b.extract_value(a, [1, op.attrs["dim"]])
    return em.b.trunc(n, LT.I32)


def _index64(em: Emitter, v: ir.Value, t: T.ScalarType) -> ir.Value:
    if t.bits == 64:
        return v
    return em.b.sext(v, LT.I64) if t.is_signed else em.b.zext(v, LT.I64)


def element_ptr(em: Emitter, arr: ir.Value, at: T.ArrayType, idx: list[Value]) -> ir.Value:
    """The address of element ``idx`` of the array ``arr`` (no bounds check)."""
    B = em.b
    off = None
    for k, iv in enumerate(idx):
        i = _index64(em, em.get(iv), iv.type)
        term = B.mul(i, B.extract_value(arr, [2, k]), flags=["nsw"])
        off = term if off is None else B.add(off, term, flags=["nsw"])
    # Struct arrays are addressed in bytes (their descriptor's strides are bytes).
    etype = LT.I8 if isinstance(at.dtype, T.StructType) else LT.memory_scalar(T.elem_type(at.dtype))
    return B.gep(B.extract_value(arr, 0), [off], inbounds=True, source_etype=etype)


def _components(em: Emitter, ptr: ir.Value, t: T.Type) -> list[ir.Value]:
    """The addresses of the scalar components of a value of ``t`` stored at ``ptr``."""
    if isinstance(t, T.ScalarType):
        return [ptr]
    mt = LT.memory_scalar(T.elem_type(t))
    return [ptr] + [
        em.b.gep(ptr, [ir.Constant(LT.I64, k)], inbounds=True, source_etype=mt)
        for k in range(1, LT.count(t))
    ]


def _fields(em: Emitter, ptr: ir.Value, t: T.StructType) -> list[tuple[ir.Value, T.Type]]:
    """(address, type) of each field of a struct stored at ``ptr`` (C layout, see types;
    ``record_dtype`` is ``storage_dtype`` extended to the records' array fields)."""
    dt = record_dtype(t)
    out = []
    for name, ft in t.fields:
        off = ir.Constant(LT.I64, dt.fields[name][1])
        out.append((em.b.gep(ptr, [off], inbounds=True, source_etype=LT.I8), ft))
    return out


def load_value(em: Emitter, ptr: ir.Value, t: T.Type) -> Any:
    """Load a value of IR type ``t`` from memory (bools are bytes there).

    A vector or matrix is loaded one scalar component at a time (consecutive
    addresses), giving ``Parts``; LLVM's vectorizers merge the loads again. A
    struct is loaded field by field at its ``storage_dtype`` offsets.
    """
    if isinstance(t, T.StructType):
        return Parts(load_value(em, p, ft) for p, ft in _fields(em, ptr, t))
    et = T.elem_type(t)
    mt, align = LT.memory_scalar(et), et.np_dtype.itemsize
    out = []
    for p in _components(em, ptr, t):
        raw = em.b.load(p, typ=mt, align=align)
        if et.is_bool:
            raw = em.b.icmp_unsigned("!=", raw, em.const(raw.type, 0))
        out.append(raw)
    return out[0] if isinstance(t, T.ScalarType) else Parts(out)


def load_record(em: Emitter, ptr: ir.Value, t: T.Type) -> Any:
    """Load a record field of IR type ``t`` (``kdsl.ir.records``): as ``load_value``, plus
    array descriptors, whose strides the record holds in bytes and registers in scalars."""
    B = em.b
    if isinstance(t, T.StructType):
        return Parts(load_record(em, p, ft) for p, ft in _fields(em, ptr, t))
    if isinstance(t, T.HandleType):
        return B.load(ptr, typ=LT.I64, align=8)
    if not isinstance(t, T.ArrayType):
        return load_value(em, ptr, t)
    desc = B.load(ptr, typ=LT.descriptor_type(t.ndim), align=8)
    unit, _ = element_strides(t)
    shift = ir.Constant(LT.I64, unit.bit_length() - 1)
    for d in range(t.ndim):
        s = B.extract_value(desc, [2, d])
        desc = B.insert_value(desc, B.ashr(s, shift, flags=["exact"]), [2, d])
    return desc


def _record(em: Emitter, op: Operation) -> Any:
    ptr = em.b.inttoptr(em.get(op.operands[0]), LT.PTR)
    block = em.b.block
    first = len(block.instructions)
    fields = load_record(em, ptr, op.results[0].type)
    # Records do not change while a kernel runs (kdsl.ir.records): marking their loads
    # invariant lets LLVM hoist them out of the thread loop instead of reloading every
    # field per thread (stores to arrays may alias them otherwise).
    invariant = block.module.add_metadata([])
    for ins in block.instructions[first:]:
        if isinstance(ins, ir.LoadInstr):
            ins.set_metadata("invariant.load", invariant)
    return fields


def store_value(em: Emitter, value: Any, ptr: ir.Value, t: T.Type) -> None:
    """Store ``value`` of IR type ``t`` to memory, one scalar component at a time."""
    if isinstance(t, T.StructType):
        for part, (p, ft) in zip(value, _fields(em, ptr, t)):
            store_value(em, part, p, ft)
        return
    et = T.elem_type(t)
    for p, x in zip(_components(em, ptr, t), components(value)):
        if et.is_bool:
            x = em.b.zext(x, LT.I8)
        em.b.store(x, p, align=et.np_dtype.itemsize)


def _load(em: Emitter, op: Operation) -> ir.Value:
    at = op.operands[0].type
    ptr = element_ptr(em, em.get(op.operands[0]), at, op.operands[1:])
    first = len(em.b.block.instructions)
    out = load_value(em, ptr, at.dtype)
    _mark(em, op.operands[0], first)
    return out


def _array_view(em: Emitter, op: Operation) -> ir.Value:
    """The descriptor of ``a[i...]``: the element address, and the remaining shape and strides."""
    at = op.operands[0].type
    arr = em.get(op.operands[0])
    k, rest = len(op.operands) - 1, op.results[0].type.ndim
    B = em.b
    out = B.insert_value(ir.Constant(LT.descriptor_type(rest), ir.Undefined),
                         element_ptr(em, arr, at, list(op.operands[1:])), 0)  # fmt: skip
    for d in range(rest):
        out = B.insert_value(out, B.extract_value(arr, [1, k + d]), [1, d])
        out = B.insert_value(out, B.extract_value(arr, [2, k + d]), [2, d])
    return out


def _store(em: Emitter, op: Operation) -> None:
    at = op.operands[1].type
    ptr = element_ptr(em, em.get(op.operands[1]), at, op.operands[2:])
    first = len(em.b.block.instructions)
    store_value(em, em.get(op.operands[0]), ptr, at.dtype)
    _mark(em, op.operands[1], first)


def _mark(em: Emitter, array: Value, first: int) -> None:
    """Put the accesses emitted since instruction ``first`` of the current block into the
    kernel's access group when ``array`` is a kernel parameter (``loop_md``)."""
    if array in em.kernel_arrays:
        mark_access(em.b.block.instructions[first:], em.access_group)


def _rmw_op(kind: str, et: T.ScalarType) -> str:
    if kind == "exch":
        return "xchg"
    if et.is_float:
        return {"add": "fadd", "sub": "fsub", "min": "fmin", "max": "fmax"}[kind]
    if kind in ("min", "max") and not et.is_signed:
        return "u" + kind
    return kind


def _rmw(em: Emitter, rmw: str, ptr: ir.Value, value: ir.Value) -> ir.Value:
    """One atomic update of a scalar; gives the old value."""
    if rmw in ("fmin", "fmax"):
        return _cas_minmax(em, rmw, ptr, value)
    return em.b.atomic_rmw(rmw, ptr, value, "monotonic")


def _cas_minmax(em: Emitter, rmw: str, ptr: ir.Value, value: ir.Value) -> ir.Value:
    """Float atomic min/max as a compare-and-swap loop on the bits.

    ``atomicrmw fmin`` follows ``minnum``, which may pick either zero for -0.0 vs
    +0.0; kdsl's min/max order the zeros (``minimumnum``), so the loop applies the
    same rule as ``arith.min``/``arith.max``. Comparing bits (not floats) makes a
    NaN in memory compare equal to itself, so the loop ends.
    """
    B = em.b
    bits = ir.IntType(_width(value.type))
    entry = B.block
    loop, done = em.new_block("cas.loop"), em.new_block("cas.done")
    first = B.load(ptr, typ=value.type, align=_width(value.type) // 8)
    B.branch(loop)
    B.position_at_end(loop)
    old = B.phi(value.type, name="cas.old")
    old.add_incoming(first, entry)
    name = "llvm.minimumnum" if rmw == "fmin" else "llvm.maximumnum"
    new = em.call_intrinsic(name, old, value)
    pair = B.cmpxchg(ptr, B.bitcast(old, bits), B.bitcast(new, bits), "monotonic", "monotonic")
    seen = B.bitcast(B.extract_value(pair, 0), value.type)
    old.add_incoming(seen, B.block)
    B.cbranch(B.extract_value(pair, 1), done, loop)
    B.position_at_end(done)
    return old


def _width(t: ir.Type) -> int:
    return {ir.HalfType: 16, ir.FloatType: 32, ir.DoubleType: 64}[type(t)]


def _atomic(em: Emitter, op: Operation) -> Any:
    at = op.operands[1].type
    et = T.elem_type(at.dtype)
    ptr = element_ptr(em, em.get(op.operands[1]), at, op.operands[2:])
    if em.local_sums is not None and op in em.local_sums:  # summed per range (local_sums)
        parts = components(em.get(op.operands[0]))
        return em.local_sums.add(em.b, op, _components(em, ptr, at.dtype), parts)
    rmw = _rmw_op(op.attrs["kind"], et)
    out = []  # componentwise: one atomic per scalar component
    for p, x in zip(_components(em, ptr, at.dtype), components(em.get(op.operands[0]))):
        if et.is_bool:  # bytes in memory; the rmw works on the byte
            old = _rmw(em, rmw, p, em.b.zext(x, LT.I8))
            old = em.b.icmp_unsigned("!=", old, em.const(old.type, 0))
        else:
            old = _rmw(em, rmw, p, x)
        out.append(old)
    return out[0] if isinstance(at.dtype, T.ScalarType) else Parts(out)


def _cas_scalar(em: Emitter, ptr: ir.Value, compare: ir.Value, value: ir.Value) -> ir.Value:
    """One ``cmpxchg`` on the bits of a scalar (LLVM's cmpxchg takes integers only)."""
    B = em.b
    t = value.type
    if isinstance(t, ir.IntType):
        return B.extract_value(B.cmpxchg(ptr, compare, value, "monotonic", "monotonic"), 0)
    bits = ir.IntType(_width(t))
    pair = B.cmpxchg(
        ptr, B.bitcast(compare, bits), B.bitcast(value, bits), "monotonic", "monotonic"
    )
    return B.bitcast(B.extract_value(pair, 0), t)


def _atomic_cas(em: Emitter, op: Operation) -> Any:
    at = op.operands[2].type
    et = T.elem_type(at.dtype)
    ptr = element_ptr(em, em.get(op.operands[2]), at, op.operands[3:])
    compares, values = components(em.get(op.operands[0])), components(em.get(op.operands[1]))
    out = []
    for p, c, x in zip(_components(em, ptr, at.dtype), compares, values):
        if et.is_bool:  # bytes in memory
            old = _cas_scalar(em, p, em.b.zext(c, LT.I8), em.b.zext(x, LT.I8))
            old = em.b.icmp_unsigned("!=", old, em.const(old.type, 0))
        else:
            old = _cas_scalar(em, p, c, x)
        out.append(old)
    return out[0] if isinstance(at.dtype, T.ScalarType) else Parts(out)


CPU.register("kd.tid", _tid)
CPU.register("kd.block_dim", lambda em, op: ir.Constant(LT.I32, 1))  # one thread a block, as Warp
CPU.register("kd.fence", lambda em, op: em.b.fence("seq_cst"))
CPU.register("kd.array_shape", _array_shape)
CPU.register("kd.load", _load)
CPU.register("kd.array_view", _array_view)
CPU.register("kd.record", _record)
CPU.register(
    "kd.null_array",
    lambda em, op: ir.Constant(LT.descriptor_type(op.results[0].type.ndim), None),
)
CPU.register("kd.store", _store)
CPU.register("kd.atomic_rmw", _atomic)
CPU.register("kd.atomic_cas", _atomic_cas)
