"""Lowering of ``kd.target_has``: a constant, true for the features the cpu backend
takes (``TARGET_FEATURES``; ``kdsl.ir.ops_target``)."""

from __future__ import annotations

from llvmlite import ir

from kdsl.backends.cpu import types as LT
from kdsl.backends.cpu.emitter import Emitter
from kdsl.ir.core import Operation
from kdsl.ir.lowering import LOWERINGS

CPU = LOWERINGS.for_backend("cpu")

#: The code paths the cpu backend compiles: the 4-wide BVH walks (``kdsl.stdlib.mesh_wide``).
TARGET_FEATURES = frozenset({"wide-tree"})


def _target_has(em: Emitter, op: Operation) -> ir.Value:
    return ir.Constant(LT.I1, int(op.attrs["feature"] in TARGET_FEATURES))


CPU.register("kd.target_has", _target_has)
