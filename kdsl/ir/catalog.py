"""The op catalog: every op is defined once, here, with all it means.

An ``OpDef`` holds an op's name, traits, type rule, verifier, folder and
interpreter semantics (its VJP joins it with autodiff; each backend's lowering is
registered in ``kdsl.ir.lowering``). Passes and backends look ops up in
``CATALOG`` by name; no second table of ops exists anywhere. Dialect files
(``ops_arith``, ``ops_math``, ``ops_vec``, ``ops_mem``, ``ops_scf``, ``ops_func``)
define their ops with ``CATALOG.define``, which returns the ``OpDef``: passes
match ops by comparing ``op.opdef`` with these (``op.opdef is ops_scf.IF``) and
ask about facts through traits, never through lists of op names. Importing
``kdsl.ir`` loads them all.

Folding: ``OpDef.folder`` evaluates an op on constant operands. A pure op with an
interpreter rule folds through that rule unless it defines its own folder, so a
folded value is exactly what the op computes at run time. ``literal_folder``
evaluates an op on untyped Python literals (``2 * 3`` in a kernel), with Python's
own arithmetic; ``fold_literal`` is what the frontend calls.

Interpreter semantics: ``interp(ctx, op, *operand_values)`` returns the result
value (one result), a tuple (several) or None (none). ``ctx`` is the interpreter's
thread context (thread index, region runner). Values are NumPy scalars, NumPy
arrays for vectors and matrices, tuples for structs and NumPy arrays for arrays.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from kdsl.ir.core import Operation
from kdsl.ir.types import Type

#: Traits an op may carry.
PURE = "pure"  # no side effects; may be CSE'd, hoisted, or removed when unused
TERMINATOR = "terminator"  # ends a block (scf.yield, func.return, scf.condition)
COMMUTATIVE = "commutative"
READS = "reads"  # reads memory (kd.load): not removable across writes
WRITES = "writes"  # writes memory (kd.store, atomics): never removed
SPECULATABLE = "speculatable"  # pure and safe to run on paths that did not ask for it
CONSTANT_LIKE = "constant_like"  # no operands, its value is an attribute (arith.constant)
INVOLUTION = "involution"  # op(op(x)) == x (arith.neg, arith.not)
#: Has no effects of its own: its effects are those of the ops in its regions
#: (scf.if/for/while; MLIR's ``RecursiveMemoryEffects``).
RECURSIVE_EFFECTS = "recursive_effects"
CHECK = "check"  # a run-time check (with WRITES): its only effect is stopping a failing thread

TypeRule = Callable[[Sequence[Type], dict[str, Any]], Sequence[Type]]
Verifier = Callable[[Operation], None]
Folder = Callable[[Operation, Sequence[Any]], Sequence[Any] | None]
InterpRule = Callable[..., Any]
LiteralFolder = Callable[..., Any]


def no_results(types: Sequence[Type], attrs: dict[str, Any]) -> Sequence[Type]:
    """Type rule of ops that give no value (terminators, stores)."""
    return []


@dataclass
class OpDef:
    """Everything kdsl knows about one op. See the module docstring."""

    name: str
    doc: str
    traits: frozenset[str] = frozenset()
    #: Result types from operand types and attributes; None when results are given
    #: explicitly by the builder (constants, casts, constructors).
    type_rule: TypeRule | None = None
    #: Extra invariants beyond the type rule; raises ``KdslVerifyError``.
    verifier: Verifier | None = None
    #: Constant folding: given constant operand values (None where unknown),
    #: return the folded result values or None. Pure ops with an interpreter
    #: rule fold through it by default when every operand is constant
    #: (``interp_folder``).
    folder: Folder | None = None
    interp: InterpRule | None = None
    #: Folding of untyped Python literals: ``literal_folder(attrs, *values)`` gives
    #: the Python number Python's own operator gives, or None when the op must be
    #: emitted on typed values instead (see ``fold_literal``).
    literal_folder: LiteralFolder | None = None
    #: Ops that reach an array element (``READS``/``WRITES``): the position of the
    #: array operand; the element's indices are the operands after it.
    array_operand: int | None = None
    #: Ops that write an operand's value into memory whatever it holds (stores and
    #: read-modify-writes, not a compare-and-swap): the position of that operand.
    stored_operand: int | None = None
    #: Number of regions the op must have.
    num_regions: int = 0
    #: Attribute names the op requires.
    required_attrs: tuple[str, ...] = ()
    #: Text-form example for the docs.
    example: str = ""
    #: Documentation group (the docs' section).
    group: str = ""
    #: Free-form extension slots (e.g. "vjp") filled by later subsystems.
    rules: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.folder is None and PURE in self.traits and self.interp is not None:
            self.folder = interp_folder(self.interp)

    @property
    def is_pure(self) -> bool:
        return PURE in self.traits

    @property
    def is_terminator(self) -> bool:
        return TERMINATOR in self.traits

    @property
    def has_side_effects(self) -> bool:
        return WRITES in self.traits

    def __hash__(self) -> int:
        return hash(self.name)

    def __eq__(self, other: object) -> bool:
        return self is other


class OpRegistry:
    """Ops by name, refusing a second definition of the same name."""

    def __init__(self) -> None:
        self._ops: dict[str, OpDef] = {}

    def define(self, name: str, doc: str, **kwargs: Any) -> OpDef:
        """Define a new op; raises ValueError if ``name`` is taken."""
        if name in self._ops:
            raise ValueError(f"op {name!r} is defined twice")
        opdef = OpDef(name=name, doc=doc, **kwargs)
        self._ops[name] = opdef
        return opdef

    def define_terminator(self, name: str, doc: str, **kwargs: Any) -> OpDef:
        """Define an op that ends a block: the ``TERMINATOR`` trait and no results."""
        return self.define(
            name, doc, traits=frozenset({TERMINATOR}), type_rule=no_results, **kwargs
        )

    def add_rule(self, name: str, rule: str, fn: Any) -> None:
        """Attach an extra rule (such as a VJP) to an existing op, once."""
        opdef = self[name]
        if rule in opdef.rules:
            raise ValueError(f"op {name!r} already has a {rule!r} rule")
        opdef.rules[rule] = fn

    def __getitem__(self, name: str) -> OpDef:
        try:
            return self._ops[name]
        except KeyError:
            raise KeyError(f"unknown op {name!r}") from None

    def __contains__(self, name: str) -> bool:
        return name in self._ops

    def get(self, name: str) -> OpDef | None:
        """The op called ``name``, or None."""
        return self._ops.get(name)

    def __iter__(self):
        return iter(self._ops.values())

    def __len__(self) -> int:
        return len(self._ops)


def interp_folder(interp: InterpRule) -> Folder:
    """The default folder of a pure op: its interpreter rule on constant operands.

    Gives None (no folding) when an operand is unknown or the rule raises (an
    out-of-range ``vec.extract``: the error must still happen at run time). The
    rule runs with ``ctx`` None (pure ops need no thread) and with NumPy's float
    warnings silenced, as at run time.
    """

    def fold(op: Operation, args: Sequence[Any]) -> list[Any] | None:
        if any(a is None for a in args):
            return None
        try:
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore")
                out = interp(None, op, *args)
        except Exception:
            return None
        if len(op.results) == 1:
            return [out]
        return list(out) if isinstance(out, tuple) else None

    return fold


CATALOG = OpRegistry()


def fold_literal(name: str, *values: Any, **attrs: Any) -> Any:
    """``name`` applied to untyped Python literals, as Python computes it.

    None when the op has no literal folder (or declines, e.g. ``2 ** -1``): the
    caller then gives the literals types and emits the op.
    """
    opdef = CATALOG.get(name)
    if opdef is None or opdef.literal_folder is None:
        return None
    return opdef.literal_folder(attrs, *values)
