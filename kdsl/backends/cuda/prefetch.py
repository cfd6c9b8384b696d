"""Lowering of ``kd.prefetch`` (``kdsl.ir.ops_prefetch``) on cuda: nothing. A GPU hides a
load's latency with other warps; the one caller, the CPU's wide mesh walk, is not
compiled for cuda anyway (``kd.target_has``)."""

from __future__ import annotations

from kdsl.backends.cuda.emitter import FuncEmitter
from kdsl.ir.core import Operation
from kdsl.ir.lowering import LOWERINGS

CUDA = LOWERINGS.for_backend("cuda")


def _prefetch(em: FuncEmitter, op: Operation) -> None:
    """A hint the cuda backend does not take: no code."""
    return None


CUDA.register("kd.prefetch", _prefetch)
