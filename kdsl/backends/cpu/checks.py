"""Lowerings of the debug checks (``kd.check_bounds``, ``kd.check_finite``) and their record.

A kernel compiled in debug mode (or with ``verify_fp``) takes one more entry in
its ``args`` array: a pointer to the error record of ``kdsl.backends.checks_common``
(its layout is there), zeroed by the launch. Internal functions get the same pointer
as an extra last parameter.

A failing check claims its slot with a compare-and-swap from 0, so only the
first failure (in time) writes the rest; a launch running on one thread (small
launches do) reports the first failure in thread order. A failed bounds check
then ends the thread: it branches to the kernel's next thread (or returns from a
called function, whose caller tests word 0 after the call and stops too), so the
bad access never runs. Every other thread runs to completion. A failed finite
check only records; the thread goes on. ``raise_for_record`` (shared with the other
backends, in ``kdsl.backends.checks_common``) turns a record into a
``KdslRuntimeError`` after the launch.
"""

from __future__ import annotations

from llvmlite import ir

from kdsl.backends import checks_common as R
from kdsl.backends.cpu import types as LT
from kdsl.backends.cpu.composite import components
from kdsl.backends.cpu.emitter import Emitter
from kdsl.errors import KdslCapabilityError
from kdsl.ir import types as T
from kdsl.ir.core import Operation
from kdsl.ir.lowering import LOWERINGS
from kdsl.ir.ops_debug import RECORD_ALIGN, RECORD_ID_END, RECORD_ID_MIN
from kdsl.ir.records import record_tag

CPU = LOWERINGS.for_backend("cpu")


def _i64(v: int) -> ir.Constant:
    return ir.Constant(LT.I64, v)


def _slot(em: Emitter, word: int) -> ir.Value:
    return em.b.gep(em.error_record, [_i64(word)], inbounds=True, source_etype=LT.I64)


def _put(em: Emitter, word: int, value: ir.Value) -> None:
    em.b.store(value, _slot(em, word), align=8)


def _record(em: Emitter, op: Operation) -> None:
    if em.error_record is None:
        raise KdslCapabilityError(
            f"{op.name} needs a debug build (compile with debug=True or verify_fp=True)", op.loc
        )


def _tid64(em: Emitter) -> ir.Value:
    return em.b.sext(em.linear, LT.I64) if em.linear is not None else _i64(-1)


def _claim(em: Emitter, word: int, site: int) -> ir.Value:
    """Atomically set ``word`` from 0 to site + 1; i1 true when this thread won."""
    pair = em.b.cmpxchg(_slot(em, word), _i64(0), _i64(site + 1), "monotonic", "monotonic")
    return em.b.extract_value(pair, 1)


def abort_thread(em: Emitter) -> None:
    """End the current thread: next thread in a kernel, return (undef) in a function."""
    if em.abort_block is not None:
        em.b.branch(em.abort_block)
        return
    ret = em.fn.function_type.return_type
    if isinstance(ret, ir.VoidType):
        em.b.ret_void()
    else:
        em.b.ret(ir.Constant(ret, ir.Undefined))


def stop_if_failed(em: Emitter) -> None:
    """After a call in a debug build: end this thread too if a bounds check failed."""
    if em.error_record is None:
        return
    B = em.b
    failed = B.icmp_unsigned("!=", B.load(_slot(em, R.BOUNDS), typ=LT.I64, align=8), _i64(0))
    stop, cont = em.new_block("call.failed"), em.new_block("call.ok")
    B.cbranch(failed, stop, cont).set_weights([1, 1000])
    B.position_at_end(stop)
    abort_thread(em)
    B.position_at_end(cont)


def _index64(em: Emitter, v: ir.Value, t: T.ScalarType) -> ir.Value:
    if t.bits == 64:
        return v
    return em.b.sext(v, LT.I64) if t.is_signed else em.b.zext(v, LT.I64)


def _check_bounds(em: Emitter, op: Operation) -> None:
    _record(em, op)
    B = em.b
    arr = em.get(op.operands[0])
    idx, shape, ok = [], [], None
    for k, iv in enumerate(op.operands[1:]):
        i = _index64(em, em.get(iv), iv.type)
        n = B.extract_value(arr, [1, k])
        # Unsigned: a negative index is a huge one, so one compare checks both ends.
        inside = B.icmp_unsigned("<", i, n)
        ok = inside if ok is None else B.and_(ok, inside)
        idx.append(i)
        shape.append(n)
    fail, write, stop, cont = (
        em.new_block(n) for n in ("bounds.fail", "bounds.write", "bounds.stop", "bounds.ok")
    )
    B.cbranch(ok, cont, fail).set_weights([1000, 1])
    B.position_at_end(fail)
    B.cbranch(_claim(em, R.BOUNDS, op.attrs["site"]), write, stop)
    B.position_at_end(write)
    _put(em, R.BOUNDS_TID, _tid64(em))
    for k in range(min(len(idx), R.MAX_NDIM)):
        _put(em, R.BOUNDS_IDX + k, idx[k])
        _put(em, R.BOUNDS_SHAPE + k, shape[k])
    B.branch(stop)
    B.position_at_end(stop)
    abort_thread(em)
    B.position_at_end(cont)


def _any(em: Emitter, flags: list[ir.Value]) -> ir.Value:
    out = flags[0]
    for f in flags[1:]:
        out = em.b.or_(out, f)
    return out


def _check_finite(em: Emitter, op: Operation) -> None:
    _record(em, op)
    B = em.b
    comps = components(em.get(op.operands[0]))
    nan = _any(em, [B.fcmp_unordered("uno", x, x) for x in comps])
    inf = _any(
        em,
        [
            B.fcmp_ordered("==", em.call_intrinsic("llvm.fabs", x), em.const(x.type, float("inf")))
            for x in comps
        ],
    )
    fail, write, cont = (em.new_block(n) for n in ("finite.fail", "finite.write", "finite.ok"))
    B.cbranch(B.or_(nan, inf), fail, cont).set_weights([1, 1000])
    B.position_at_end(fail)
    B.cbranch(_claim(em, R.FP, op.attrs["site"]), write, cont)
    B.position_at_end(write)
    _put(em, R.FP_TID, _tid64(em))
    _put(em, R.FP_KIND, B.select(nan, _i64(1), _i64(2)))
    B.branch(cont)
    B.position_at_end(cont)


def _check_record(em: Emitter, op: Operation) -> None:
    _record(em, op)
    B = em.b
    rid = em.get(op.operands[0])
    read, fail, write, stop, cont = (
        em.new_block(n) for n in ("record.read", "record.fail", "record.write", "record.stop",
                                  "record.ok")
    )  # fmt: skip
    # only a plausible address is read (RECORD_ID_MIN <= rid < RECORD_ID_END, aligned)
    span = B.icmp_unsigned("<", B.sub(rid, _i64(RECORD_ID_MIN)), _i64(RECORD_ID_END - RECORD_ID_MIN))
    aligned = B.icmp_unsigned("==", B.and_(rid, _i64(RECORD_ALIGN - 1)), _i64(0))
    B.cbranch(B.and_(span, aligned), read, fail).set_weights([1000, 1])
    B.position_at_end(read)
    word = B.load(B.inttoptr(rid, LT.PTR), typ=LT.I64, align=8)
    tag = ir.Constant(LT.I64, record_tag(op.attrs["arg"]))
    B.cbranch(B.icmp_unsigned("==", word, tag), cont, fail).set_weights([1000, 1])
    B.position_at_end(fail)
    B.cbranch(_claim(em, R.BOUNDS, op.attrs["site"]), write, stop)
    B.position_at_end(write)
    _put(em, R.BOUNDS_TID, _tid64(em))
    _put(em, R.BOUNDS_IDX, rid)
    B.branch(stop)
    B.position_at_end(stop)
    abort_thread(em)
    B.position_at_end(cont)


CPU.register("kd.check_bounds", _check_bounds)
CPU.register("kd.check_record", _check_record)
CPU.register("kd.check_finite", _check_finite)
