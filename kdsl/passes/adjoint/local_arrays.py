"""Thread-local arrays (``kd.local_array``) in the adjoint.

A local array is memory of the thread, so the adjoint recomputes its contents instead
of reading them back: the forward replay repeats the writes into local arrays (which
the kernel's other writes are not), and a region the reverse sweep replays again (a
branch, a loop body) repeats the writes into the local arrays it creates itself.

What stays out of reach is refused here, precisely, rather than differentiated wrong:

- a read of a local array, inside a branch or a reversed loop, of an array that was
  created outside that region and is written: the reverse sweep would replay the read
  with the array's final contents (``check_local_reads``);
- a gradient through a local array: a read whose value reaches a gradient, of an array
  that holds values computed at run time (``check_no_gradient``). The values a kernel
  stores in local arrays get no gradient (as in Warp, where ``fixedarray`` is not
  differentiable); keep differentiable values in registers or global arrays.
"""

from __future__ import annotations

from kdsl.errors import KdslError
from kdsl.ir import Operation, Value
from kdsl.ir.catalog import CONSTANT_LIKE
from kdsl.ir.ops_local import is_local_array
from kdsl.passes.adjoint.analysis import Primal, base_array


def local_base(op: Operation) -> Value | None:
    """The local array whose element ``op`` reaches (through views), or None."""
    at = op.opdef.array_operand
    if at is None:
        return None
    base = base_array(op.operands[at])
    return base if is_local_array(base) else None


def _is_write(op: Operation) -> bool:
    return op.name in ("kd.store", "kd.atomic_rmw", "kd.atomic_cas")


def _is_read(op: Operation) -> bool:
    return op.name == "kd.load" or (_is_write(op) and bool(op.results and op.results[0].uses))


def _enclosing(op: Operation) -> Operation | None:
    """The op whose region holds ``op`` (None at the top)."""
    block = op.parent
    region = block.parent if block is not None else None
    return region.parent if region is not None else None


def _replayed_by(primal: Primal, op: Operation) -> Operation | None:
    """The innermost branch or reversed loop around ``op``, which the reverse sweep replays."""
    parent = _enclosing(op)
    while parent is not None and parent is not primal.func:
        if parent.name == "scf.if" or (
            parent.name in ("scf.for", "scf.while") and primal.matters(parent)
        ):
            return parent
        parent = _enclosing(parent)
    return None


def _inside(op: Operation, region_op: Operation) -> bool:
    parent = _enclosing(op)
    while parent is not None:
        if parent is region_op:
            return True
        parent = _enclosing(parent)
    return False


def check_local_reads(primal: Primal) -> None:
    """Refuse reads the reverse sweep would replay with stale local-array contents."""
    written = {local_base(op) for op in primal.func.walk() if _is_write(op)}
    for op in primal.func.walk():
        base = local_base(op)
        if base is None or base not in written or not _is_read(op):
            continue
        region = _replayed_by(primal, op)
        if region is not None and not _inside(base.op, region):
            name = base.name_hint or "local array"
            raise KdslError(
                f"kdsl cannot differentiate this read of the local array '{name}': it is "
                "inside a branch or loop that the backward pass replays, but the array is "
                "created and written outside it, so the replay would read its final "
                "contents. Create the local array inside that branch or loop, or launch "
                "this kernel without a backward pass (enable_backward=False)",
                op.loc, primal.sym,
            )  # fmt: skip


def check_no_gradient(primal: Primal, load: Operation) -> None:
    """Refuse a gradient reaching ``load`` of a local array that holds computed values."""
    base = local_base(load)
    if base is None:
        return
    for op in primal.func.walk():
        if not _is_write(op) or local_base(op) is not base:
            continue
        value = op.operands[1] if op.name == "kd.atomic_cas" else op.operands[0]
        src = getattr(value, "op", None)
        if src is None or CONSTANT_LIKE not in src.opdef.traits:
            name = base.name_hint or "local array"
            raise KdslError(
                f"kdsl cannot differentiate through the local array '{name}': this read "
                "reaches a gradient, and the array holds values computed at run time, "
                "which local arrays carry no gradient for (Warp's fixedarray neither). Keep "
                "differentiable values in variables or global arrays, or launch this kernel "
                "without a backward pass (enable_backward=False)",
                load.loc, primal.sym,
            )  # fmt: skip
