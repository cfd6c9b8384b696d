"""The adjoint function of one kernel: its signature, then replay and reverse sweep.

``AdjointBuilder(module, kernel).build()`` adds ``<kernel>__adj``, whose parameters
are the kernel's, one adjoint per parameter (``adj_<name>``, same type: gradient
arrays for arrays), then hidden ones from ``hidden_from`` on (the tapes, the tape
status, the ``grad_owned`` mask), added as the sweeps need them. ``build_counter()``
then adds the counting function when a tape's size is only known at run time.
"""

from __future__ import annotations

from kdsl.ir import Builder, Module, Operation, Value, new_func
from kdsl.ir.types import I32
from kdsl.passes.adjoint.analysis import Primal, check_differentiable
from kdsl.passes.adjoint.counting import build_counter
from kdsl.passes.adjoint.local_arrays import check_local_reads
from kdsl.passes.adjoint.replay import Replay
from kdsl.passes.adjoint.reverse import ReverseSweep
from kdsl.passes.adjoint.tapes import TapeTable, TapeWriter

ADJ_SUFFIX = "__adj"


class AdjointBuilder:
    """Builds ``<kernel>__adj`` (and ``<kernel>__count``) next to a kernel."""

    def __init__(self, module: Module, kernel: Operation) -> None:
        self.primal = Primal(module, kernel)
        self.tapes = TapeTable(self.primal.sym)

    def build(self) -> Operation:
        """Add and return the adjoint function."""
        primal = self.primal
        check_differentiable(primal)
        check_local_reads(primal)
        args = primal.block.args
        types = [a.type for a in args]
        names = [a.name_hint for a in args]
        adj_names = [f"adj_{n or i}" for i, n in enumerate(names)]
        func = new_func(
            primal.module, primal.sym + ADJ_SUFFIX, types + types, names + adj_names, [],
            "kernel", primal.func.loc, {"adjoint_of": primal.sym},
        )  # fmt: skip
        body = func.regions[0].block
        n = len(args)
        # Hidden parameters (tapes, flags) follow the 2n parameters and adjoints.
        func.attrs["hidden_from"] = 2 * n
        vmap: dict[Value, Value] = {a: body.args[i] for i, a in enumerate(args)}
        grads = {a: body.args[n + i] for i, a in enumerate(args) if a in primal.grad_arrays}
        b = Builder(body)
        with b.at(primal.func.loc):
            ltid = b.create("kd.tid", [], [I32], {"dim": 0, "ndim": 1}).result
        writer = TapeWriter(self.tapes, b, body, ltid)
        replay = Replay(primal, b, writer)
        sweep = ReverseSweep(primal, b, replay, writer, grads, body)
        replay.replay(primal.block, vmap, record=True)
        replay.local_writes = False  # the reverse sweep's replays: see ``local_arrays``
        sweep.reverse_block(primal.block, vmap, {})
        b.create("func.return", loc=primal.func.loc)
        writer.finish(func)
        return func

    def build_counter(self) -> Operation | None:
        """Add the counting function (after ``build``); None when every tape size is static."""
        return build_counter(self.primal, self.tapes)
