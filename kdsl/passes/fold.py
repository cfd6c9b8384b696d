"""Constant folding through the op catalog's folders.

A pure op whose operands are all ``arith.constant`` is evaluated by its catalog
``folder`` and its scalar results become constants. An op's folder is its own hook
where it defines one, else its ``interp`` rule (``kdsl.ir.catalog.interp_folder``;
``ctx`` is None: pure ops need no thread context). Control flow folds when its
condition is constant: ``scf.if`` is replaced by the region that runs,
``arith.select`` by the chosen value, and an ``scf.for`` that runs no iteration by
its initial values.

Invariants: results are bit-exact with what the interpreter computes at run time
(the catalog rule *is* the run-time semantics), so no float reassociation ever
happens. An op whose folder raises or declines (an out-of-range ``vec.extract``) is
left alone, so the error still happens at run time.

Options: ``max_iters`` bounds the rounds over the module (each round folds what the
previous one exposed).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from kdsl.ir import Module, Operation, Value
from kdsl.ir.catalog import CONSTANT_LIKE, PURE
from kdsl.ir.ops_arith import SELECT
from kdsl.ir.ops_scf import FOR, IF
from kdsl.ir.rewrite import (
    constant_of,
    inline_block_before,
    make_constant,
    replace_op,
    rewrite_module,
)
from kdsl.ir.semantics import np_value
from kdsl.ir.types import ScalarType
from kdsl.passes.manager import ModulePass


def _constants(values: list[Value]) -> list[Any] | None:
    out = []
    for v in values:
        ok, c = constant_of(v)
        if not ok:
            return None
        out.append(np_value(c, v.type))
    return out


def _evaluate(op: Operation, args: list[Any]) -> list[Any] | None:
    """The op's results from constant operands, or None if it cannot (or must not) fold."""
    folder = op.opdef.folder
    if folder is None:
        return None
    try:
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            out = folder(op, args)
    except Exception:
        # The op would fail at run time (or the rule needs a context): keep it.
        return None
    return None if out is None else list(out)


def _fold_pure(op: Operation) -> bool:
    traits = op.opdef.traits
    if PURE not in traits or op.regions or not op.operands or not op.results:
        return False
    if CONSTANT_LIKE in traits:
        return False
    if not all(isinstance(r.type, ScalarType) for r in op.results):
        return False
    args = _constants(op.operands)
    if args is None:
        return False
    out = _evaluate(op, args)
    if out is None or len(out) != len(op.results):
        return False
    try:
        values = [make_constant(v, r.type, op) for v, r in zip(out, op.results)]
    except (TypeError, ValueError):
        return False
    for v, r in zip(values, op.results):
        v.name_hint = r.name_hint
    replace_op(op, values)
    return True


def _fold_if(op: Operation) -> bool:
    ok, cond = constant_of(op.operands[0])
    if not ok:
        return False
    region = op.regions[0] if cond else op.regions[1]
    replace_op(op, inline_block_before(region.block, op, ()))
    return True


def _fold_select(op: Operation) -> bool:
    ok, cond = constant_of(op.operands[0])
    if not ok:
        return False
    replace_op(op, [op.operands[1] if cond else op.operands[2]])
    return True


def _fold_for(op: Operation) -> bool:
    bounds = [constant_of(v) for v in op.operands[:3]]
    if not all(ok for ok, _ in bounds):
        return False
    lb, ub, step = (int(c) for _, c in bounds)
    runs = (step > 0 and lb < ub) or (step < 0 and lb > ub)
    if runs:
        return False
    replace_op(op, list(op.operands[3:]))
    return True


_CONTROL = {IF: _fold_if, SELECT: _fold_select, FOR: _fold_for}


def fold_op(op: Operation) -> bool:
    """Fold one op if its operands allow; returns whether it was replaced."""
    rule = _CONTROL.get(op.opdef)
    if rule is not None:
        return rule(op)
    return _fold_pure(op)


@dataclass(frozen=True)
class FoldPass(ModulePass):
    """Constant folding (see the module docstring)."""

    name: ClassVar[str] = "fold"
    #: Upper bound on rounds over the module.
    max_iters: int = 8

    def apply(self, module: Module) -> bool:
        return rewrite_module(module, fold_op, rounds=self.max_iters)
