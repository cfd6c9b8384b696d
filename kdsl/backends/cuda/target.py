"""Lowering of ``kd.target_has``: a constant, true for the features the cuda backend
takes (``TARGET_FEATURES``, none: a GPU walks meshes' binary trees; ``kdsl.ir.ops_target``).
NVRTC drops the code behind a ``false``."""

from __future__ import annotations

from kdsl.backends.cuda.emitter import FuncEmitter
from kdsl.ir.core import Operation
from kdsl.ir.lowering import LOWERINGS

CUDA = LOWERINGS.for_backend("cuda")

#: The code paths the cuda backend compiles (``kdsl.ir.ops_target.FEATURES``): none.
TARGET_FEATURES: frozenset[str] = frozenset()


def _target_has(em: FuncEmitter, op: Operation) -> str:
    return "true" if op.attrs["feature"] in TARGET_FEATURES else "false"


CUDA.register("kd.target_has", _target_has)
