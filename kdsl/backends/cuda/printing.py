"""``kd.print`` on the cuda backend: CUDA's device ``printf``.

The format (``kdsl.ir.ops_print.c_format``) is written as a C string literal in
which only letters, digits, spaces and a few punctuation marks stand for
themselves; every other byte (quotes, backslashes, ``?``, ``*``, ``/``, newlines,
non-ASCII) is a three-digit octal escape, so no format can end the literal, open
a comment or form a trigraph. Operands already have their conversion's C vararg
type; a bool for ``%s`` becomes ``"True"`` or ``"False"``. The device buffers the
output and the driver writes it at the next synchronization.
"""

from __future__ import annotations

import string

from kdsl.backends.cuda.emitter import FuncEmitter
from kdsl.ir.core import Operation
from kdsl.ir.lowering import LOWERINGS
from kdsl.ir.ops_print import c_format

CUDA = LOWERINGS.for_backend("cuda")

#: Bytes written as themselves inside a generated string literal.
_PLAIN = frozenset((string.ascii_letters + string.digits + " %.,:;=+-_()[]<>{}!#&|^~@$'").encode())


def c_string_literal(text: str) -> str:
    """``text`` (UTF-8) as a C string literal that is safe to paste into generated code."""
    return '"' + "".join(chr(b) if b in _PLAIN else f"\\{b:03o}" for b in text.encode()) + '"'


def _print(em: FuncEmitter, op: Operation) -> None:
    args = [c_string_literal(c_format(op.attrs["format"]))]
    for v in op.operands:
        x = em.get(v)
        args.append(f'({x} ? "True" : "False")' if v.type.is_bool else x)
    em.line(f"printf({', '.join(args)});", op.loc)


CUDA.register("kd.print", _print)
