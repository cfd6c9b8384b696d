"""The ``scf`` dialect: structured control flow whose regions yield values.

Semantics follow MLIR's ``scf``:

- ``scf.if %c : T...`` has a *then* and an *else* region; each ends with
  ``scf.yield`` of values of the result types.
- ``scf.for %lb, %ub, %step, %init... : T...`` runs its body with the induction
  variable and the carried values as block arguments; the body yields the next
  carried values; the results are the final ones. Like Python's ``range``: the
  loop runs while ``iv < ub`` for a positive step and ``iv > ub`` for a negative
  one; a zero step runs no iteration.
- ``scf.while %init... : T...`` has a *before* region (arguments: the carried
  values) ending in ``scf.condition %c, %v...``; when ``%c`` is true the *after*
  region runs with ``%v...`` and yields the next carried values; when false the
  op's results are ``%v...``.

``ctx.run_region(region, args)`` runs a region in the interpreter and returns the
operands of its terminator.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from kdsl.ir.catalog import CATALOG, RECURSIVE_EFFECTS, OpDef
from kdsl.ir.types import BOOL, ScalarType, Type


def _types(values) -> list[Type]:
    return [v.type for v in values]


def _fmt(ts: Sequence[Type]) -> str:
    return "(" + ", ".join(map(str, ts)) + ")"


def _define_structured(name: str, doc: str, **kwargs: Any) -> OpDef:
    """A structured op: its effects are those of the ops in its regions."""
    return CATALOG.define(
        name, doc, traits=frozenset({RECURSIVE_EFFECTS}), group="control flow", **kwargs
    )


def _check_yield(region, want: Sequence[Type], what: str, term: str = "scf.yield") -> None:
    t = region.block.terminator
    if t is None or t.name != term:
        raise TypeError(f"the {what} region must end with {term}")
    got = _types(t.operands[1:] if term == "scf.condition" else t.operands)
    if got != list(want):
        raise TypeError(f"the {what} region yields {_fmt(got)} but {_fmt(want)} is expected")


def _if_verify(op) -> None:
    if op.operands[0].type != BOOL or len(op.operands) != 1:
        raise TypeError("scf.if takes one bool condition")
    rts = _types(op.results)
    for region, what in zip(op.regions, ("then", "else")):
        if region.block.args:
            raise TypeError(f"the {what} region of scf.if takes no arguments")
        _check_yield(region, rts, what)


def _if_interp(ctx, op, cond):
    out = ctx.run_region(op.regions[0] if cond else op.regions[1], ())
    return _results(op, out)


def _results(op, values: Sequence[Any]):
    if len(op.results) == 1:
        return values[0]
    return tuple(values) if op.results else None


IF = _define_structured(
    "scf.if",
    "Run the then region if the condition holds, else the else region; the results "
    "are what the region that ran yields.",
    verifier=_if_verify, interp=_if_interp, num_regions=2,
    example="%1 = scf.if %0 : f32 {\n  scf.yield %a\n} {\n  scf.yield %b\n}",
)  # fmt: skip


def _for_verify(op) -> None:
    if len(op.operands) < 3:
        raise TypeError("scf.for needs a lower bound, upper bound and step")
    lb, ub, step = (v.type for v in op.operands[:3])
    if not (isinstance(lb, ScalarType) and lb.is_int and lb == ub == step):
        raise TypeError(f"scf.for bounds must be integers of one type, got {lb}, {ub}, {step}")
    carried = _types(op.operands[3:])
    if _types(op.results) != carried:
        raise TypeError("scf.for results must match its initial carried values")
    body = op.regions[0].block
    if _types(body.args) != [lb, *carried]:
        raise TypeError("scf.for body arguments must be the induction variable and carried values")
    _check_yield(op.regions[0], carried, "body")


def _for_interp(ctx, op, lb, ub, step, *init):
    carried = list(init)
    iv_t = type(lb)
    i, ub_, st = int(lb), int(ub), int(step)
    body = op.regions[0]
    while (st > 0 and i < ub_) or (st < 0 and i > ub_):
        carried = list(ctx.run_region(body, (iv_t(i), *carried)))
        i += st
    return _results(op, carried)


FOR = _define_structured(
    "scf.for", "A counted loop with loop-carried values (see the module docstring).",
    verifier=_for_verify, interp=_for_interp, num_regions=1,
    example="%3 = scf.for %lb, %ub, %st, %x0 : f32 {\n^bb(%i: i32, %x: f32):\n"
    "  %y = arith.add %x, %x : f32\n  scf.yield %y\n}",
)  # fmt: skip

#: The ``scf.for`` attribute the ``block-cache`` pass sets (the tile length in elements);
#: here so that a backend can read it without importing the pass.
BLOCK_CACHE_ATTR = "block_cache"


def _while_verify(op) -> None:
    carried = _types(op.operands)
    before, after = op.regions[0].block, op.regions[1].block
    if _types(before.args) != carried:
        raise TypeError("scf.while before-region arguments must match the initial values")
    cond = before.terminator
    if cond is None or cond.name != "scf.condition":
        raise TypeError("the before region of scf.while must end with scf.condition")
    passed = _types(cond.operands[1:])
    if _types(op.results) != passed:
        raise TypeError("scf.while results must match the values scf.condition passes on")
    if _types(after.args) != passed:
        raise TypeError("scf.while after-region arguments must match scf.condition's values")
    _check_yield(op.regions[1], carried, "after")


def _while_interp(ctx, op, *init):
    carried = list(init)
    before, after = op.regions
    while True:
        cond, *passed = ctx.run_region(before, carried)
        if not cond:
            return _results(op, passed)
        carried = list(ctx.run_region(after, passed))


WHILE = _define_structured(
    "scf.while", "A loop with a condition region and a body region (see the module docstring).",
    verifier=_while_verify, interp=_while_interp, num_regions=2,
    example='%r = scf.while %x0 : i32 {\n^bb(%x: i32):\n'
    '  %c = arith.cmp %x, %n {pred = "lt"} : bool\n  scf.condition %c, %x\n} {\n'
    "^bb(%y: i32):\n  %z = arith.add %y, %one : i32\n  scf.yield %z\n}",
)  # fmt: skip


def _condition_verify(op) -> None:
    if not op.operands or op.operands[0].type != BOOL:
        raise TypeError("scf.condition takes a bool condition first")


def _parent_name(op) -> str | None:
    p = op.parent_op()
    return p.name if p is not None else None


def _yield_verify(op) -> None:
    if _parent_name(op) not in ("scf.if", "scf.for", "scf.while"):
        raise TypeError("scf.yield must end a region of scf.if, scf.for or scf.while")


YIELD = CATALOG.define_terminator(
    "scf.yield", "Ends a region of scf.if/for/while, passing values to the parent op.",
    verifier=_yield_verify, example="scf.yield %0, %1", group="control flow",
)  # fmt: skip
CONDITION = CATALOG.define_terminator(
    "scf.condition", "Ends the before region of scf.while: a bool, then the values passed on.",
    verifier=_condition_verify, example="scf.condition %c, %x", group="control flow",
)  # fmt: skip
