"""``kd.print``: formatted output from kernel threads (``print``/``printf``).

``kd.print %a, %b {format = "x=%d y=%g\\n"}`` writes its format with each
conversion replaced by the next operand. The format language is C's ``printf``
without length modifiers, ``*`` widths, ``%n`` and ``%p``, and with one fixed
operand type per conversion, so every backend formats the same bytes:

====================  ===========  ==========================================
conversion            operand      prints
====================  ===========  ==========================================
``d`` ``i``           ``i64``      signed decimal
``u`` ``o`` ``x`` ``X``  ``u64``   unsigned decimal, octal, hex
``f F e E g G``       ``f64``      C's float formats
``c``                 ``i32``      one byte
``s``                 ``bool``     ``True`` or ``False`` (kdsl has no strings)
``%%``                (none)       a literal ``%``
====================  ===========  ==========================================

The frontend (``kdsl.frontend.printing``) checks a user's format against the
argument types and casts each argument to its conversion's type. Backends emit
the format through ``c_format`` (C ``printf`` needs ``ll`` before 64-bit integer
conversions) or ``format_values`` (the reference formatter). Lines printed by
different threads may interleave in any order, as with CUDA's device printf.
"""

from __future__ import annotations

import math
import re
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from kdsl.ir.catalog import CATALOG, WRITES
from kdsl.ir.core import Operation
from kdsl.ir.types import BOOL, F64, I32, I64, U64, Type

#: A conversion: flags, width, precision, length modifier, conversion character.
_SPEC = re.compile(r"%([-+ #0]*)(\*|\d+)?(?:\.(\*|\d*))?(hh|h|ll|l|j|z|t|L)?(.?)", re.S)

#: The operand type of each conversion.
CONVERSION_TYPES: dict[str, Type] = {
    **dict.fromkeys("di", I64), **dict.fromkeys("uoxX", U64),
    **dict.fromkeys("fFeEgG", F64), "c": I32, "s": BOOL,
}  # fmt: skip


@dataclass(frozen=True)
class Conversion:
    """One ``%...`` of a format: ``start``/``end`` are its span in the format."""

    flags: str
    width: str
    precision: str | None
    length: str
    conv: str
    start: int
    end: int

    def text(self, conv: str | None = None, length: str = "") -> str:
        """The conversion re-spelled (without its length modifier unless given)."""
        prec = "" if self.precision is None else "." + self.precision
        return f"%{self.flags}{self.width}{prec}{length}{conv or self.conv}"


class FormatError(ValueError):
    """A malformed format; ``pos`` is the offending conversion's offset."""

    def __init__(self, msg: str, pos: int) -> None:
        super().__init__(msg)
        self.pos = pos


def parse_format(fmt: str) -> list[str | Conversion]:
    """``fmt`` as literal text pieces and conversions (``%%`` becomes the text ``%``).

    Raises ``FormatError`` for conversions kdsl does not support (``*`` widths,
    ``%n``, ``%p``, ``%a``, an unknown or missing conversion character).
    """
    out: list[str | Conversion] = []
    pos = 0
    for m in re.finditer("%", fmt):
        if m.start() < pos:
            continue  # the second '%' of a '%%'
        if m.start() > pos:
            out.append(fmt[pos : m.start()])
        spec = _SPEC.match(fmt, m.start())
        assert spec is not None  # the pattern matches any '%'
        flags, width, prec, length, conv = spec.groups()
        if conv == "%" and not (flags or width or prec is not None or length):
            out.append("%")
            pos = spec.end()
            continue
        if width == "*" or prec == "*":
            raise FormatError("'*' widths and precisions are not supported", m.start())
        if not conv:
            raise FormatError("a '%' ends the format (write '%%' for a percent sign)", m.start())
        if conv not in CONVERSION_TYPES:
            text = fmt[m.start() : spec.end()]
            raise FormatError(f"unsupported conversion '{text}' (write '%%' for a percent sign)",
                              m.start())  # fmt: skip
        if conv == "o" and "#" in flags:
            raise FormatError("the '#' flag of '%o' is not supported", m.start())
        out.append(Conversion(flags, width or "", prec, length or "", conv, m.start(), spec.end()))
        pos = spec.end()
    if pos < len(fmt):
        out.append(fmt[pos:])
    return out


def conversions(fmt: str) -> list[Conversion]:
    """The conversions of ``fmt``, in order."""
    return [p for p in parse_format(fmt) if isinstance(p, Conversion)]


def canonical(pieces: Sequence[str | Conversion]) -> str:
    """The IR format of parsed pieces: literal ``%`` doubled, no length modifiers."""
    return "".join(p.replace("%", "%%") if isinstance(p, str) else p.text() for p in pieces)


def c_format(fmt: str) -> str:
    """``fmt`` (an IR format) for C's ``printf``: ``ll`` before 64-bit integer conversions."""
    return "".join(
        p.replace("%", "%%") if isinstance(p, str)
        else p.text(length="ll" if p.conv in "diuoxX" else "")
        for p in parse_format(fmt)
    )  # fmt: skip


def _format_one(c: Conversion, v: Any) -> str:
    spec = c.text()
    if c.conv == "s":
        return spec % ("True" if bool(v) else "False")
    if c.conv in "fFeEgG":
        x = float(v)
        if math.isnan(x):
            # C libraries print the sign of a NaN ("-nan"); keep the width and flags.
            s = spec % math.copysign(math.inf, x)
            return s.replace("inf", "nan").replace("INF", "NAN")
        return spec % x
    n = int(v)
    if c.conv in "xX" and n == 0:
        spec = spec.replace("#", "")  # C prints a zero without the 0x prefix
    return spec % n


def format_values(fmt: str, values: Sequence[Any]) -> str:
    """The text ``kd.print`` writes for an IR format and its operand values."""
    out = []
    it = iter(values)
    for p in parse_format(fmt):
        out.append(p if isinstance(p, str) else _format_one(p, next(it)))
    return "".join(out)


def _print_verify(op: Operation) -> None:
    fmt = op.attrs["format"]
    if not isinstance(fmt, str):
        raise TypeError("kd.print needs a string format")
    try:
        convs = conversions(fmt)
    except FormatError as e:
        raise TypeError(f"kd.print: {e}") from None
    if len(convs) != len(op.operands):
        raise TypeError(
            f"kd.print: the format has {len(convs)} conversions but there are "
            f"{len(op.operands)} operands"
        )
    for k, (c, v) in enumerate(zip(convs, op.operands)):
        want = CONVERSION_TYPES[c.conv]
        if v.type != want or c.length:
            raise TypeError(
                f"kd.print: operand {k} of '{c.text(length=c.length)}' must be a {want} "
                f"(no length modifier), not a {v.type}"
            )


def _print_interp(ctx, op, *values):
    sys.stdout.write(format_values(op.attrs["format"], values))


CATALOG.define(
    "kd.print",
    "Write ``format`` with each conversion replaced by the next operand (C ``printf`` "
    "conversions, one operand type each: ``%d``/``%i`` i64, ``%u %o %x %X`` u64, "
    "``%f %e %g`` (and capitals) f64, ``%c`` i32, ``%s`` bool as True/False).",
    traits=frozenset({WRITES}),
    type_rule=lambda ts, attrs: [],
    verifier=_print_verify,
    interp=_print_interp,
    required_attrs=("format",),
    example='kd.print %0, %1 {format = "i=%d x=%g\\n"}',
    group="debug",
)
