"""The interior box of a launch: where a kernel's bounds tests have known answers.

``kdsl.passes.thread_interior`` gives a kernel's cuts (``t_d >= p`` or ``t_d < p``
per bounds test) and a copy of its body with those tests folded. Here the cuts
become LLVM values, once per launch, before the thread loop: per thread dimension
``d`` the interior is ``lo[d] <= t_d < hi[d]`` (i64), clamped to ``[0, extent)``.
``lower`` then runs the folded copy on the interior columns of each row and the
kernel's own body on the rest, in one loop for both edges (boundary peeling), so a
stencil's inner loop has no branch and vectorizes.
"""

from __future__ import annotations

from llvmlite import ir

from kdsl.backends.cpu import types as LT
from kdsl.backends.cpu.emitter import Emitter
from kdsl.passes.thread_interior import InteriorPlan, cut_position, wrap_limit


def interior_box(
    em: Emitter, plan: InteriorPlan, extents: list[ir.Value]
) -> tuple[list[ir.Value], list[ir.Value]]:
    """``(lo, hi)`` per thread dimension (i64): the box of ``plan``'s interior.

    ``extents`` are the launch's extents (i64, one per dimension). Lowers the ops
    computing the cuts first; they read only parameters and constants.
    """
    B = em.b
    for op in plan.invariant_ops:
        em.lower_op(op)
    lo = [ir.Constant(LT.I64, 0) for _ in extents]
    hi = list(extents)
    for cut in plan.cuts:
        value, k = cut_position(cut)
        pos: ir.Value = ir.Constant(LT.I64, k)
        if value is not None:
            pos = B.add(B.sext(em.get(value), LT.I64), pos)
        d = cut.dim
        if cut.low:
            lo[d] = _smax(B, lo[d], pos)
        else:
            hi[d] = _smin(B, hi[d], pos)
        limit = wrap_limit(cut)
        if limit is not None:
            hi[d] = _smin(B, hi[d], ir.Constant(LT.I64, limit))
    return lo, hi


def inside(em: Emitter, lo: ir.Value, hi: ir.Value, t: ir.Value) -> ir.Value:
    """``lo <= t < hi`` for an i32 index ``t`` (i1)."""
    B = em.b
    t64 = B.sext(t, LT.I64)
    return B.and_(B.icmp_signed("<=", lo, t64), B.icmp_signed("<", t64, hi))


def split_range(
    em: Emitter, first: ir.Value, last: ir.Value, lo: ir.Value, hi: ir.Value
) -> tuple[ir.Value, ir.Value]:
    """``(a, b)`` with ``first <= a <= b <= last``: ``[a, b)`` is ``[first, last) ∩ [lo, hi)``.

    With an empty intersection ``a == b``, and the edge parts ``[first, a)`` and
    ``[b, last)`` cover the whole range.
    """
    B = em.b
    a = _smin(B, _smax(B, lo, first), last)
    b = _smax(B, _smin(B, hi, last), a)
    return a, b


def _smax(B: ir.IRBuilder, x: ir.Value, y: ir.Value) -> ir.Value:
    return B.select(B.icmp_signed(">", x, y), x, y)


def _smin(B: ir.IRBuilder, x: ir.Value, y: ir.Value) -> ir.Value:
    return B.select(B.icmp_signed("<", x, y), x, y)
