"""The gradient function of one function, for ``kdsl.grad(f)(args)`` (Warp's ``wp.grad``).

``build_function_vjp(func, into, sym)`` adds to module ``into`` a ``kind = "func"``
function ``sym`` with ``func``'s parameters that returns, for each parameter, the
derivative of ``func``'s results with respect to it, each result's adjoint seeded with
ones (Warp's ``adj_ret = T(1)``: for a vector result, the sum of its components'
gradients). It is the reverse sweep kernels use (``replay``, ``reverse``) run on a
function: the forward values are replayed, then the ops are walked backwards through
their VJP rules. The gradient is ordinary IR, so it inlines, optimizes and runs on
every backend, and a kernel's own adjoint can differentiate through it.

``func`` must be call-free (inline it first). A parameter that is not differentiable
(an integer, an array) gets a zero (a null array) as its gradient, and nothing flows
into arrays the function reads. A loop that carries a differentiable value has no
gradient here: kernels reverse such loops over tapes the runtime allocates, which a
function called inside a thread cannot have; it is refused with its location.
"""

from __future__ import annotations

from collections.abc import Iterable

from kdsl.errors import KdslError
from kdsl.ir import Builder, Module, Operation, Value, new_func
from kdsl.ir.vjp import VjpContext, is_differentiable
from kdsl.passes.adjoint.analysis import Primal
from kdsl.passes.adjoint.replay import Replay
from kdsl.passes.adjoint.reverse import ReverseSweep
from kdsl.passes.adjoint.tapes import LoopTape


class _NoTapes:
    """The tape sink of a function's gradient: a loop that needs a tape is refused."""

    every_loop = False

    def __init__(self, what: str) -> None:
        self.what = what

    def tape(self, op: Operation) -> LoopTape:
        raise KdslError(
            f"{self.what}: this loop carries a value the gradient depends on, and kdsl "
            "reverses such loops only in whole kernels (over tapes the launch allocates); "
            "differentiate the kernel instead (kdsl.Tape), or unroll the loop with "
            "kdsl.static(range(n)) when its trip count is a compile-time constant",
            op.loc,
        )

    def store(self, tape: LoopTape, k: Value, values: Iterable[Value]) -> None:
        raise AssertionError("no tapes")

    def record_trips(self, tape: LoopTape, slots: Value) -> None:
        raise AssertionError("no tapes")


def build_function_vjp(func: Operation, into: Module, sym: str, what: str) -> Operation:
    """Add the gradient function of call-free ``func`` to ``into`` as ``sym`` (see the
    module docstring); ``what`` names it in errors (``grad(f)``)."""
    primal = Primal(into, func)
    args = primal.block.args
    types = [a.type for a in args]
    out = new_func(into, sym, types, [a.name_hint for a in args], types, "func", func.loc)
    body = out.regions[0].block
    b = Builder(body)
    sink = _NoTapes(what)
    replay = Replay(primal, b, sink)
    sweep = ReverseSweep(primal, b, replay, sink, {}, body)  # type: ignore[arg-type]
    vmap: dict[Value, Value] = dict(zip(args, body.args))
    ctx = VjpContext(b, vmap.__getitem__)
    with b.at(func.loc):
        replay.replay(primal.block, vmap, record=True)
        adj: dict[Value, Value] = {}
        for r in primal.block.terminator.operands:
            if not is_differentiable(r.type):
                raise KdslError(f"{what}: the function returns a {r.type}, which has no "
                                "gradient", func.loc)  # fmt: skip
            sweep.accumulate(adj, r, ctx.const(1, r.type))
        replay.local_writes = False
        sweep.reverse_block(primal.block, vmap, adj)
        # A parameter without a gradient (an integer, an array) gets its type's zero, as
        # Warp's zero-initialized adjoints.
        grads = [adj.get(a) or ctx.zeros(a.type) for a in args]
        b.create("func.return", grads)
    return out
