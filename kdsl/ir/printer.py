"""Printing IR in kdsl's MLIR-like text form. ``parser.parse_module`` reads it back.

Grammar of one op (regions follow on the same line and nest by braces)::

    [%r, ... =] NAME [%a, %b, ...] [{key = value, ...}] [: T, ...] [{ region } ...]
        [loc("file":line:col:end_line:end_col)]

A region prints ``^bb(%x: T, ...):`` first when its block has arguments. A
function prints as ``func.func @name(%x: T, ...) -> (R, ...) {attrs} { ... }``.
Value names come from name hints (``%x``, ``%x_1`` when taken) or are numbered.
Locations are printed only when asked (``debuginfo=True``).
"""

from __future__ import annotations

import json
import math
import re
from typing import Any

from kdsl.ir.core import Block, Loc, Module, Operation, Region, Value
from kdsl.ir.types import Type

_FUNC_ATTRS = ("sym_name", "res_types")
_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def format_attr(value: Any) -> str:
    """The text of one attribute value."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(format_attr(v) for v in value) + "]"
    if isinstance(value, Type):
        return f"type({value})"
    raise TypeError(f"cannot print attribute value {value!r}")


def format_loc(loc: Loc) -> str:
    parts = [json.dumps(loc.file), str(loc.line), str(loc.col)]
    if loc.end_line is not None and loc.end_col is not None:
        parts += [str(loc.end_line), str(loc.end_col)]
    return "loc(" + ":".join(parts) + ")"


class Printer:
    """Prints one module; owns the value-name table."""

    def __init__(self, debuginfo: bool = False) -> None:
        self.debuginfo = debuginfo
        self.names: dict[int, str] = {}
        self.taken: set[str] = set()
        self.counter = 0
        self.lines: list[str] = []

    def name(self, v: Value) -> str:
        key = id(v)
        if key not in self.names:
            hint = v.name_hint
            if hint and _IDENT.fullmatch(hint) and not hint[0].isdigit():
                cand, n = hint, 0
                while cand in self.taken:
                    n += 1
                    cand = f"{hint}_{n}"
            else:
                while str(self.counter) in self.taken:
                    self.counter += 1
                cand = str(self.counter)
                self.counter += 1
            self.taken.add(cand)
            self.names[key] = cand
        return "%" + self.names[key]

    def print_module(self, module: Module) -> str:
        for st in module.structs.values():
            self.lines.append(st.definition())
        if module.structs:
            self.lines.append("")
        for i, func in enumerate(module.funcs):
            if i:
                self.lines.append("")
            self.print_func(func)
        return "\n".join(self.lines) + "\n"

    def print_func(self, func: Operation) -> None:
        # Names are scoped to a function so each reads on its own.
        self.names, self.taken, self.counter = {}, set(), 0
        block = func.regions[0].block
        args = ", ".join(f"{self.name(a)}: {a.type}" for a in block.args)
        res = ", ".join(str(t) for t in func.attrs.get("res_types", []))
        head = f"func.func @{func.attrs['sym_name']}({args}) -> ({res})"
        attrs = {k: v for k, v in func.attrs.items() if k not in _FUNC_ATTRS}
        if attrs:
            head += " " + self.format_attrs(attrs)
        self.lines.append(head + " {")
        self.print_block_ops(block, 1)
        self.lines.append("}" + self.loc_suffix(func.loc))

    def format_attrs(self, attrs: dict[str, Any]) -> str:
        return "{" + ", ".join(f"{k} = {format_attr(v)}" for k, v in sorted(attrs.items())) + "}"

    def loc_suffix(self, loc: Loc) -> str:
        return " " + format_loc(loc) if self.debuginfo else ""

    def print_block_ops(self, block: Block, depth: int) -> None:
        for op in block.ops:
            self.print_op(op, depth)

    def print_op(self, op: Operation, depth: int) -> None:
        pad = "  " * depth
        text = ""
        if op.results:
            text += ", ".join(self.name(r) for r in op.results) + " = "
        text += op.name
        if op.operands:
            text += " " + ", ".join(self.name(v) for v in op.operands)
        if op.attrs:
            text += " " + self.format_attrs(op.attrs)
        if op.results:
            text += " : " + ", ".join(str(r.type) for r in op.results)
        if not op.regions:
            self.lines.append(pad + text + self.loc_suffix(op.loc))
            return
        for i, region in enumerate(op.regions):
            self.lines.append(pad + (text if i == 0 else "}") + " {")
            self.print_region_body(region, depth + 1)
        self.lines.append(pad + "}" + self.loc_suffix(op.loc))

    def print_region_body(self, region: Region, depth: int) -> None:
        block = region.block
        if block.args:
            args = ", ".join(f"{self.name(a)}: {a.type}" for a in block.args)
            self.lines.append("  " * (depth - 1) + f"^bb({args}):")
        self.print_block_ops(block, depth)


def print_module(module: Module, debuginfo: bool = False) -> str:
    """The text form of ``module``."""
    return Printer(debuginfo).print_module(module)


def print_op(op: Operation, debuginfo: bool = False) -> str:
    """The text form of one op (a function prints whole)."""
    p = Printer(debuginfo)
    if op.name == "func.func":
        p.print_func(op)
    else:
        p.print_op(op, 0)
    return "\n".join(p.lines)
