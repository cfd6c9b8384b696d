"""Parsing the text form that ``printer`` writes, so print -> parse -> print is exact.

``//`` starts a comment that runs to the end of the line, so FileCheck test files
(``// RUN:``, ``// CHECK:``) parse as they are. Errors are ``KdslVerifyError`` with
the line and column in the text.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from typing import Any, TypeVar

from kdsl.errors import KdslVerifyError
from kdsl.ir.builder import create_op
from kdsl.ir.catalog import CATALOG
from kdsl.ir.core import Block, Loc, Module, Operation, Region, Value
from kdsl.ir.types import (
    SCALARS,
    ArrayType,
    HandleType,
    MatrixType,
    QuatType,
    StructType,
    TransformType,
    Type,
    VectorType,
)

_TOKEN = re.compile(
    r"""
    (?P<ws>[ \t\r\n]+|//[^\n]*)
  | (?P<value>%[A-Za-z0-9_]+)
  | (?P<symbol>@[A-Za-z_][A-Za-z0-9_]*)
  | (?P<string>"(?:[^"\\]|\\.)*")
  | (?P<number>-?(?:\d+\.\d*(?:[eE][+-]?\d+)?|\d+[eE][+-]?\d+|\d+))
  | (?P<ident>[A-Za-z_][A-Za-z0-9_.]*)
  | (?P<arrow>->)
  | (?P<punct>[(){}<>,:=\[\]^-])
    """,
    re.VERBOSE,
)


T = TypeVar("T")

_NAMED_VECTORS = {cls.keyword: cls for cls in (QuatType, TransformType)}
_COMPOSITE_TYPES = frozenset({"vec", "mat", "array", "struct", "handle", *_NAMED_VECTORS})


class _Tok:
    __slots__ = ("kind", "text", "line", "col")

    def __init__(self, kind: str, text: str, line: int, col: int) -> None:
        self.kind, self.text, self.line, self.col = kind, text, line, col


def _tokenize(text: str, file: str) -> list[_Tok]:
    toks: list[_Tok] = []
    pos, line, line_start = 0, 1, 0
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None:
            col = pos - line_start + 1
            raise KdslVerifyError(
                f"unexpected character {text[pos]!r} in IR text", Loc(file, line, col)
            )
        kind = m.lastgroup or ""
        tok = m.group()
        if kind != "ws":
            toks.append(_Tok(kind, tok, line, pos - line_start + 1))
        newlines = tok.count("\n")
        if newlines:
            line += newlines
            line_start = pos + tok.rindex("\n") + 1
        pos = m.end()
    toks.append(_Tok("eof", "", line, pos - line_start + 1))
    return toks


class Parser:
    """Recursive-descent parser for one module."""

    def __init__(self, text: str, file: str = "<ir>") -> None:
        self.file = file
        self.toks = _tokenize(text, file)
        self.pos = 0
        self.module = Module()
        self.scopes: list[dict[str, Value]] = []

    # --- token helpers -----------------------------------------------------

    @property
    def tok(self) -> _Tok:
        return self.toks[self.pos]

    def peek(self, offset: int = 1) -> _Tok:
        return self.toks[min(self.pos + offset, len(self.toks) - 1)]

    def loc(self, tok: _Tok | None = None) -> Loc:
        t = tok or self.tok
        return Loc(self.file, t.line, t.col)

    def error(self, message: str, tok: _Tok | None = None) -> KdslVerifyError:
        t = tok or self.tok
        found = t.text or "end of input"
        return KdslVerifyError(f"{message} (found {found!r})", self.loc(t))

    def at(self, text: str) -> bool:
        return self.tok.text == text and self.tok.kind in ("punct", "ident", "arrow")

    def accept(self, text: str) -> bool:
        if self.at(text):
            self.pos += 1
            return True
        return False

    def expect(self, text: str) -> _Tok:
        if not self.at(text):
            raise self.error(f"expected {text!r}")
        tok = self.tok
        self.pos += 1
        return tok

    def expect_kind(self, kind: str, what: str) -> _Tok:
        if self.tok.kind != kind:
            raise self.error(f"expected {what}")
        tok = self.tok
        self.pos += 1
        return tok

    def parse_list(self, close: str, parse_item: Callable[[], T]) -> list[T]:
        """Comma-separated items up to ``close`` (consumed); the opening is already read."""
        items: list[T] = []
        while not self.accept(close):
            if items:
                self.expect(",")
            items.append(parse_item())
        return items

    def parse_separated(self, parse_item: Callable[[], T]) -> list[T]:
        """One item or more, separated by commas."""
        items = [parse_item()]
        while self.accept(","):
            items.append(parse_item())
        return items

    def parse_typed_name(self, kind: str, what: str) -> tuple[_Tok, Type]:
        """``name: type`` (a struct field, a function or block argument)."""
        tok = self.expect_kind(kind, what)
        self.expect(":")
        return tok, self.parse_type()

    # --- module level --------------------------------------------------------

    def parse_module(self) -> Module:
        while self.tok.kind != "eof":
            if self.at("struct"):
                self.parse_struct()
            elif self.at("func.func"):
                self.module.add_func(self.parse_func())
            else:
                raise self.error("expected 'struct' or 'func.func'")
        return self.module

    def parse_struct(self) -> None:
        self.expect("struct")
        name = self.expect_kind("ident", "a struct name").text
        align = self.parse_int() if self.accept("align") else 0
        self.expect("{")
        fields = self.parse_list("}", lambda: self.parse_typed_name("ident", "a field name"))
        self.module.add_struct(StructType(name, tuple((tok.text, t) for tok, t in fields), align))

    def parse_func(self) -> Operation:
        start = self.expect("func.func")
        name = self.expect_kind("symbol", "a function name like @f").text[1:]
        self.scopes = [{}]
        self.expect("(")
        args = self.parse_list(")", lambda: self.parse_typed_name("value", "an argument like %x"))
        self.expect("->")
        res_types = self.parse_type_list_parens()
        attrs = self.parse_attrs() if self.at_attrs() else {}
        block = Block([t for _, t in args], [self.hint(tok.text) for tok, _ in args])
        for (tok, _), arg in zip(args, block.args):
            self.define(tok, arg)
        attrs = {"sym_name": name, **attrs, "res_types": res_types}
        self.expect("{")
        self.parse_ops_until_brace(block)
        func = Operation(CATALOG["func.func"], (), (), attrs, [Region(block)], self.loc(start))
        if self.at("loc"):
            func.loc = self.parse_loc()
        return func

    # --- ops -----------------------------------------------------------------

    def parse_ops_until_brace(self, block: Block) -> None:
        while not self.accept("}"):
            block.append(self.parse_op())

    def parse_op(self) -> Operation:
        start = self.tok
        result_toks: list[_Tok] = []
        if self.tok.kind == "value":
            result_toks = self.parse_separated(lambda: self.expect_kind("value", "a value"))
            self.expect("=")
        name_tok = self.expect_kind("ident", "an op name")
        if name_tok.text not in CATALOG:
            raise self.error("unknown op", name_tok)
        operands: list[Value] = []
        # Operands start on the op's line: a value on the next line starts the next op
        # (after an op with neither operands nor results, such as ``kd.fence``).
        if self.tok.kind == "value" and self.tok.line == name_tok.line:
            operands = self.parse_separated(lambda: self.use(self.expect_kind("value", "a value")))
        attrs = self.parse_attrs() if self.at_attrs() else {}
        result_types: list[Type] = []
        if self.accept(":"):
            result_types = self.parse_separated(self.parse_type)
        if len(result_types) != len(result_toks):
            raise self.error(
                f"{name_tok.text} names {len(result_toks)} results but gives "
                f"{len(result_types)} types", name_tok,
            )  # fmt: skip
        regions: list[Region] = []
        while self.at("{"):
            regions.append(self.parse_region())
        try:
            op = create_op(name_tok.text, operands, result_types, attrs, regions, self.loc(start))
        except (TypeError, ValueError) as e:
            raise KdslVerifyError(str(e), self.loc(name_tok)) from None
        if self.at("loc"):
            op.loc = self.parse_loc()
        for tok, r in zip(result_toks, op.results):
            r.name_hint = self.hint(tok.text)
            self.define(tok, r)
        return op

    def parse_region(self) -> Region:
        self.expect("{")
        self.scopes.append({})
        block = Block()
        if self.accept("^"):
            self.expect_kind("ident", "a block label")
            self.expect("(")

            def block_arg() -> None:
                tok, t = self.parse_typed_name("value", "a block argument")
                self.define(tok, block.add_arg(t, self.hint(tok.text)))

            self.parse_list(")", block_arg)
            self.expect(":")
        self.parse_ops_until_brace(block)
        self.scopes.pop()
        return Region(block)

    # --- values ----------------------------------------------------------------

    @staticmethod
    def hint(text: str) -> str | None:
        name = text[1:]
        return None if name[:1].isdigit() else name

    def define(self, tok: _Tok, value: Value) -> None:
        for scope in self.scopes:
            if tok.text in scope:
                raise self.error(f"value {tok.text} is defined twice", tok)
        self.scopes[-1][tok.text] = value

    def use(self, tok: _Tok) -> Value:
        for scope in reversed(self.scopes):
            if tok.text in scope:
                return scope[tok.text]
        raise self.error(f"use of undefined value {tok.text}", tok)

    # --- attributes, types, locations ------------------------------------------

    def at_attrs(self) -> bool:
        return self.at("{") and self.peek().kind == "ident" and self.peek(2).text == "="

    def parse_attrs(self) -> dict[str, Any]:
        self.expect("{")
        return dict(self.parse_list("}", self.parse_attr))

    def parse_attr(self) -> tuple[str, Any]:
        key = self.expect_kind("ident", "an attribute name").text
        self.expect("=")
        return key, self.parse_attr_value()

    def parse_attr_value(self) -> Any:
        tok = self.tok
        if tok.kind == "number":
            self.pos += 1
            text = tok.text
            return float(text) if any(c in text for c in ".eE") else int(text)
        if tok.kind == "string":
            self.pos += 1
            return json.loads(tok.text)
        if self.accept("-"):
            self.expect("inf")
            return float("-inf")
        if self.accept("["):
            return self.parse_list("]", self.parse_attr_value)
        words = {"true": True, "false": False, "inf": float("inf"), "nan": float("nan")}
        if tok.kind == "ident" and tok.text in words:
            self.pos += 1
            return words[tok.text]
        if self.accept("type"):
            self.expect("(")
            t = self.parse_type()
            self.expect(")")
            return t
        raise self.error("expected an attribute value")

    def parse_type_list_parens(self) -> list[Type]:
        self.expect("(")
        return self.parse_list(")", self.parse_type)

    def parse_int(self) -> int:
        tok = self.expect_kind("number", "an integer")
        return int(tok.text)

    def parse_type(self) -> Type:
        tok = self.expect_kind("ident", "a type")
        name = tok.text
        if name in SCALARS:
            return SCALARS[name]
        if name not in _COMPOSITE_TYPES:
            raise self.error(f"unknown type {name!r}", tok)
        self.expect("<")
        if name == "vec":
            n = self.parse_int()
            self.expect(",")
            t: Type = VectorType(n, self.parse_scalar())
        elif name == "mat":
            r = self.parse_int()
            self.expect(",")
            c = self.parse_int()
            self.expect(",")
            t = MatrixType(r, c, self.parse_scalar())
        elif name in _NAMED_VECTORS:
            t = _NAMED_VECTORS[name](self.parse_scalar())
        elif name == "array":
            dtype = self.parse_type()
            self.expect(",")
            t = ArrayType(dtype, self.parse_int())
        elif name == "struct":
            sname = self.expect_kind("ident", "a struct name")
            if sname.text not in self.module.structs:
                raise self.error(f"struct {sname.text} is not defined", sname)
            t = self.module.structs[sname.text]
        elif name == "handle":
            t = HandleType(self.expect_kind("ident", "a handle kind").text)
        else:
            raise self.error("unknown type", tok)
        self.expect(">")
        return t

    def parse_scalar(self):
        tok = self.tok
        t = self.parse_type()
        if t not in SCALARS.values():
            raise self.error("expected a scalar type", tok)
        return t

    def parse_loc(self) -> Loc:
        self.expect("loc")
        self.expect("(")
        file = json.loads(self.expect_kind("string", "a file name").text)
        nums = []
        while self.accept(":"):
            nums.append(self.parse_int())
        self.expect(")")
        if len(nums) == 2:
            return Loc(file, nums[0], nums[1])
        if len(nums) == 4:
            return Loc(file, *nums)
        raise self.error("a location has a line and column, and optionally an end")


def parse_module(text: str, file: str = "<ir>", verify: bool = True) -> Module:
    """Parse the text form of a module; verifies it unless ``verify=False``."""
    module = Parser(text, file).parse_module()
    if verify:
        from kdsl.ir.verifier import verify_module

        verify_module(module)
    return module
