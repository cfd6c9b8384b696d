"""Building IR: an insertion point and op creation through the catalog's type rules."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any

from kdsl.ir.catalog import CATALOG
from kdsl.ir.core import UNKNOWN_LOC, Block, Loc, Module, Operation, Region, Value
from kdsl.ir.types import Type


def create_op(
    name: str,
    operands: Sequence[Value] = (),
    result_types: Sequence[Type] | None = None,
    attrs: dict[str, Any] | None = None,
    regions: Sequence[Region] = (),
    loc: Loc = UNKNOWN_LOC,
) -> Operation:
    """A new, unattached op. Result types come from the op's type rule when omitted.

    Raises ``TypeError`` (with a user-facing message) when the type rule rejects the
    operands; the frontend turns that into a located ``KdslTypeError``.
    """
    opdef = CATALOG[name]
    if result_types is None:
        if opdef.type_rule is None:
            raise ValueError(f"{name} needs explicit result types")
        result_types = list(opdef.type_rule([v.type for v in operands], dict(attrs or {})))
    return Operation(opdef, operands, result_types, attrs, regions, loc)


def normalize_constant(value: Any, type: Type) -> bool | int | float:
    """``value`` rounded to ``type`` (a scalar) as a plain Python bool, int or float."""
    from kdsl.ir.semantics import np_value

    v = np_value(value, type)
    if type.is_bool:  # type: ignore[attr-defined]
        return bool(v)
    if type.is_float:  # type: ignore[attr-defined]
        return float(v)
    return int(v)


class Builder:
    """Appends ops at an insertion point: the end of a block, or before an op."""

    def __init__(self, block: Block | None = None, before: Operation | None = None) -> None:
        self.block = block
        self.before = before
        self.loc: Loc = UNKNOWN_LOC

    def insert(self, op: Operation) -> Operation:
        if self.block is None:
            raise ValueError("builder has no insertion point")
        if self.before is not None:
            self.block.insert_before(self.before, op)
        else:
            self.block.append(op)
        return op

    def create(
        self,
        name: str,
        operands: Sequence[Value] = (),
        result_types: Sequence[Type] | None = None,
        attrs: dict[str, Any] | None = None,
        regions: Sequence[Region] = (),
        loc: Loc | None = None,
    ) -> Operation:
        """Create an op (see ``create_op``) and insert it."""
        op = create_op(name, operands, result_types, attrs, regions, loc or self.loc)
        return self.insert(op)

    def value(self, name: str, *operands: Value, loc: Loc | None = None, **attrs: Any) -> Value:
        """Create a single-result op and return its result."""
        return self.create(name, operands, None, attrs or None, loc=loc).result

    def constant(self, value: Any, type: Type, loc: Loc | None = None) -> Value:
        """A scalar ``arith.constant`` (the value is stored exactly at ``type``'s width)."""
        value = normalize_constant(value, type)
        return self.create("arith.constant", (), [type], {"value": value}, loc=loc).result

    @contextmanager
    def at_end(self, block: Block) -> Iterator[Builder]:
        """Temporarily insert at the end of ``block``."""
        saved = (self.block, self.before)
        self.block, self.before = block, None
        try:
            yield self
        finally:
            self.block, self.before = saved

    @contextmanager
    def at(self, loc: Loc) -> Iterator[Builder]:
        """Temporarily stamp new ops with ``loc``."""
        saved = self.loc
        self.loc = loc
        try:
            yield self
        finally:
            self.loc = saved


def new_func(
    module: Module,
    name: str,
    arg_types: Sequence[Type],
    arg_names: Sequence[str | None],
    res_types: Sequence[Type],
    kind: str,
    loc: Loc = UNKNOWN_LOC,
    extra_attrs: dict[str, Any] | None = None,
) -> Operation:
    """Append an empty ``func.func`` (no terminator yet) to ``module``."""
    body = Block(arg_types, arg_names)
    attrs = {"sym_name": name, "kind": kind, "res_types": list(res_types)}
    attrs.update(extra_attrs or {})
    func = Operation(CATALOG["func.func"], (), (), attrs, [Region(body)], loc)
    module.add_func(func)
    return func
