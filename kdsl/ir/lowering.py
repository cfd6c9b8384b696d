"""Lowering rules by (op, backend): one registry, duplicates refused.

Each backend registers how it lowers each op of the catalog, next to the rule
(JAX's ``register_lowering(prim, rule, platform=...)``); its emitter dispatches
through ``LOWERINGS.table(backend)``, a plain dict lookup by op name. What a rule
is depends on the backend: ``fn(emitter, op)`` for cpu and cuda, the op's
``interp`` rule for the interpreter. Besides rules, a backend may declare for an op:

- a *gap*: it cannot lower the op, and says why (a capability it lacks); a kernel
  using the op fails with a capability error;
- that the op is *structural*: lowered inside another lowering, not on its own
  (``func.func`` by the backend's function driver). Terminators are structural on
  every backend without a declaration: the lowering of the op or function owning
  their region reads their operands;
- a *default*: a rule derived from the op catalog for every op it has no explicit
  rule for (the interpreter runs each op's ``interp`` rule).

Every op of the catalog must be covered on every built-in backend by one of these
(tests/ir/test_lowering_coverage.py); ``docs/ir.md`` shows the coverage per op.
A second registration for the same (op, backend), of any kind, raises
``ValueError`` naming both places.

Registering::

    from kdsl.ir.lowering import LOWERINGS

    CPU = LOWERINGS.for_backend("cpu")
    CPU.register("arith.add", binary(_method("add"), _method("fadd")))

    @CPU.rule("arith.neg")
    def _neg(em, op): ...

    CPU.structural("func.func", "`lower.emit_kernel` (kernels), `lower.declare_func`")
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, Literal

from kdsl.ir.catalog import CATALOG, TERMINATOR, OpDef

Rule = Callable[..., Any]
#: How an op is covered on a backend.
Kind = Literal["rule", "default", "structural", "gap"]


@dataclass(frozen=True)
class Coverage:
    """How one backend handles one op.

    ``kind`` is ``"rule"`` (registered), ``"default"`` (derived from the catalog),
    ``"structural"`` or ``"gap"``; ``note`` says how or why (empty for rules);
    ``origin`` is where the declaration was made (``file:line``).
    """

    op: str
    backend: str
    kind: Kind
    rule: Rule | None = None
    note: str = ""
    origin: str = ""


def _op_name(op: str | OpDef) -> str:
    name = op.name if isinstance(op, OpDef) else op
    if name not in CATALOG:
        raise KeyError(f"cannot register a lowering of {name!r}: the op catalog has no such op")
    return name


def _caller(depth: int) -> str:
    """``file:line`` of the code ``depth`` frames above the caller of this function."""
    frame = sys._getframe(depth + 1)
    return f"{frame.f_code.co_filename}:{frame.f_lineno}"


def _describe(c: Coverage) -> str:
    what = getattr(c.rule, "__qualname__", None) if c.rule is not None else c.kind
    return f"{c.origin} ({what})"


#: How every backend covers a terminator (see the module docstring).
TERMINATOR_NOTE = "a terminator: the lowering of the op or function owning its region reads it"


class LoweringRegistry:
    """Lowerings, gaps and structural ops per backend (see the module docstring)."""

    def __init__(self) -> None:
        #: backend -> op name -> rule: the dispatch tables, registered rules only.
        self._tables: dict[str, dict[str, Rule]] = {}
        #: (op name, backend) -> its declaration (rules, gaps, structural ops).
        self._declared: dict[tuple[str, str], Coverage] = {}
        #: backend -> (rule of an op from its definition, what that rule is, origin).
        self._defaults: dict[str, tuple[Callable[[OpDef], Rule | None], str, str]] = {}

    # -- declaring ----------------------------------------------------------------
    def _declare(self, c: Coverage) -> None:
        prev = self._declared.get((c.op, c.backend))
        if prev is not None:
            raise ValueError(
                f"backend {c.backend!r} declares {c.op} twice: first at {_describe(prev)}, "
                f"again at {_describe(c)}"
            )
        self._declared[(c.op, c.backend)] = c
        self._tables.setdefault(c.backend, {})
        if c.rule is not None:
            self._tables[c.backend][c.op] = c.rule

    def register(self, op: str | OpDef, backend: str, fn: Rule, *, _depth: int = 1) -> Rule:
        """Register ``fn`` as ``backend``'s lowering of ``op``; gives ``fn`` back."""
        if not callable(fn):
            raise TypeError(f"the lowering of {op} for {backend!r} must be callable, not {fn!r}")
        self._declare(Coverage(_op_name(op), backend, "rule", fn, "", _caller(_depth)))
        return fn

    def lowering(self, op: str | OpDef, backend: str) -> Callable[[Rule], Rule]:
        """Decorator form of ``register``."""

        def deco(fn: Rule) -> Rule:
            return self.register(op, backend, fn, _depth=2)

        return deco

    def declare_gap(self, op: str | OpDef, backend: str, reason: str, *, _depth: int = 1) -> None:
        """Record that ``backend`` cannot lower ``op``, and why (the capability it lacks)."""
        if not reason.strip():
            raise ValueError(f"a gap of {backend!r} for {op} needs a reason")
        self._declare(Coverage(_op_name(op), backend, "gap", None, reason, _caller(_depth)))

    def declare_structural(
        self, op: str | OpDef, backend: str, how: str, *, _depth: int = 1
    ) -> None:
        """Record that ``backend`` lowers ``op`` inside another lowering (``how`` says where)."""
        if not how.strip():
            raise ValueError(f"structural op {op} of {backend!r} needs a note on how it is lowered")
        self._declare(Coverage(_op_name(op), backend, "structural", None, how, _caller(_depth)))

    def set_default(
        self, backend: str, rule_of: Callable[[OpDef], Rule | None], what: str, *, _depth: int = 1
    ) -> None:
        """Derive ``backend``'s rule for ops it registers nothing for: ``rule_of(opdef)``.

        ``what`` names the derived rule for the docs ("the op's interp rule").
        """
        if backend in self._defaults:
            raise ValueError(f"backend {backend!r} has a default lowering already")
        self._defaults[backend] = (rule_of, what, _caller(_depth))
        self._tables.setdefault(backend, {})

    def for_backend(self, backend: str) -> BackendLowerings:
        """A registrar bound to ``backend`` (what a backend's lowering modules use)."""
        return BackendLowerings(self, backend)

    # -- looking up ---------------------------------------------------------------
    def table(self, backend: str) -> dict[str, Rule]:
        """The dispatch table of ``backend``: op name -> registered rule.

        It is the registry's own dict (an emitter keeps it and looks ops up in it);
        add to it only through ``register``.
        """
        return self._tables.setdefault(backend, {})

    def get(self, op: str | OpDef, backend: str) -> Rule | None:
        """``backend``'s rule for ``op`` (registered, else its default), or None."""
        c = self.coverage(op, backend)
        return c.rule if c is not None else None

    def coverage(self, op: str | OpDef, backend: str) -> Coverage | None:
        """How ``backend`` handles ``op``, or None when it declares nothing for it."""
        name = op.name if isinstance(op, OpDef) else op
        c = self._declared.get((name, backend))
        if c is not None:
            return c
        opdef = CATALOG.get(name)
        if opdef is not None and TERMINATOR in opdef.traits:
            return Coverage(name, backend, "structural", None, TERMINATOR_NOTE, __name__)
        default = self._defaults.get(backend)
        if default is None or name not in CATALOG:
            return None
        rule_of, what, origin = default
        rule = rule_of(CATALOG[name])
        if rule is None:
            return None
        return Coverage(name, backend, "default", rule, what, origin)

    def backends(self) -> list[str]:
        """Names of the backends that declared anything, sorted."""
        return sorted(self._tables)

    def uncovered(self, backend: str, ops: Iterable[OpDef] | None = None) -> list[str]:
        """Ops (of the catalog by default) that ``backend`` neither lowers nor declares."""
        return [
            o.name for o in (CATALOG if ops is None else ops) if self.coverage(o, backend) is None
        ]


@dataclass(frozen=True)
class BackendLowerings:
    """``LOWERINGS`` bound to one backend: ``register``, ``rule``, ``gap``, ``structural``."""

    registry: LoweringRegistry
    backend: str

    def register(self, op: str | OpDef, fn: Rule) -> Rule:
        """Register ``fn`` as this backend's lowering of ``op``."""
        return self.registry.register(op, self.backend, fn, _depth=2)

    def rule(self, op: str | OpDef) -> Callable[[Rule], Rule]:
        """Decorator: register the decorated function as the lowering of ``op``."""

        def deco(fn: Rule) -> Rule:
            return self.registry.register(op, self.backend, fn, _depth=2)

        return deco

    def gap(self, op: str | OpDef, reason: str) -> None:
        """Declare that this backend cannot lower ``op`` (``reason``: the capability missing)."""
        self.registry.declare_gap(op, self.backend, reason, _depth=2)

    def structural(self, op: str | OpDef, how: str) -> None:
        """Declare that ``op`` is lowered inside another lowering (``how`` says which)."""
        self.registry.declare_structural(op, self.backend, how, _depth=2)


#: The registry every backend registers its lowerings in.
LOWERINGS = LoweringRegistry()
register_lowering = LOWERINGS.register
lowering = LOWERINGS.lowering
declare_gap = LOWERINGS.declare_gap
declare_structural = LOWERINGS.declare_structural
