"""Lowerings of structured control flow and calls to C's own ``if``, ``for``, ``while``.

Results of an ``scf`` op are variables declared before the statement and
assigned where the region yields. Loop-carried values are those same variables:
the body reads them as its block arguments and the yield updates them (as a
parallel assignment), so after the loop they hold the results.
"""

from __future__ import annotations

from kdsl.backends.cuda import checks, tiling
from kdsl.backends.cuda.emitter import FuncEmitter
from kdsl.ir import types as T
from kdsl.ir.core import Operation, OpResult, Value
from kdsl.ir.lowering import LOWERINGS

CUDA = LOWERINGS.for_backend("cuda")


def _declare_results(em: FuncEmitter, op: Operation) -> list[str]:
    return [em.declare(r.type) for r in op.results]


def _if(em: FuncEmitter, op: Operation) -> list[str]:
    out = _declare_results(em, op)
    types = [r.type for r in op.results]
    em.open(f"if ({em.get(op.operands[0])}) {{")
    em.assign(out, em.lower_block(op.regions[0].block), types)
    else_block = op.regions[1].block
    if out or len(else_block.ops) > 1:
        em.depth -= 1
        em.open("} else {")
        em.assign(out, em.lower_block(else_block), types)
    em.close()
    return out


def _for(em: FuncEmitter, op: Operation) -> list[str]:
    shared = tiling.tiled_loads(em, op)
    if shared:
        return tiling.lower_tiled_for(em, op, shared)
    lb, ub, step, *init = em.args(op)
    it: T.ScalarType = op.operands[0].type
    types = [r.type for r in op.results]
    carried = [em.declare(t, v) for t, v in zip(types, init)]
    iv = em.fresh()
    c = em.ctype(it)
    step_const = _const_of(op.operands[2])
    if step_const is not None and step_const > 0:
        cond = f"{iv} < {ub}"
    elif step_const is not None and step_const < 0:
        cond = f"{iv} > {ub}"
    elif it.is_signed:  # like range(): a negative step counts down, zero runs nothing
        cond = f"({step} > 0 ? {iv} < {ub} : ({step} < 0 && {iv} > {ub}))"
    else:
        cond = f"{step} != 0 && {iv} < {ub}"
    em.open(f"for ({c} {iv} = {lb}; {cond}; {iv} = ({c})({iv} + {step})) {{")
    nxt = em.lower_block(op.regions[0].block, [iv, *carried])
    em.assign(carried, nxt, types)
    em.close()
    return carried


def _const_of(v: Value) -> int | None:
    """The value of a constant integer operand (to write a plain loop test), else None."""
    if isinstance(v, OpResult) and v.op.name == "arith.constant":
        return int(v.op.attrs["value"])
    return None


def _while(em: FuncEmitter, op: Operation) -> list[str]:
    types = [v.type for v in op.operands]
    carried = [em.declare(t, v) for t, v in zip(types, em.args(op))]
    out = _declare_results(em, op)
    em.open("while (true) {")
    cond, *passed = em.lower_block(op.regions[0].block, carried)
    em.open(f"if (!{cond}) {{")
    em.assign(out, passed, [r.type for r in op.results])
    em.line("break;")
    em.close()
    nxt = em.lower_block(op.regions[1].block, passed)
    em.assign(carried, nxt, types)
    em.close()
    return out


def _call(em: FuncEmitter, op: Operation) -> list[str]:
    callee = op.attrs["callee"]
    name = em.src.func_name(callee)
    if callee not in em.src.funcs_todo:
        em.src.funcs_todo.append(callee)
    args = em.args(op)
    if em.src.debug:
        args.append("kd_err")
    call = f"{name}({', '.join(args)})"
    if not op.results:
        em.line(f"{call};")
        checks.stop_if_failed(em)
        return []
    if len(op.results) == 1:
        r = em.declare(op.results[0].type, call)
        checks.stop_if_failed(em)
        return [r]
    tmp = em.fresh()
    em.line(f"{em.src.ret_struct([r.type for r in op.results])} {tmp} = {call};")
    checks.stop_if_failed(em)
    return [em.declare(r.type, f"{tmp}.r{i}") for i, r in enumerate(op.results)]


CUDA.register("scf.if", _if)
CUDA.register("scf.for", _for)
CUDA.register("scf.while", _while)
CUDA.register("func.call", _call)

# Ops lowered as part of another lowering, never on their own.
CUDA.structural("func.func", "`lower._kernel` (`__global__`), `lower._function` (`__device__`)")
