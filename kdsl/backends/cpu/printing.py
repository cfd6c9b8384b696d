"""``kd.print`` on the cpu backend: a call to the C library's ``printf``.

The format (``kdsl.ir.ops_print.c_format``) is a private constant byte array of
the LLVM module, so no user text is ever parsed as code. Operands already have
their conversion's type (i64, u64, f64, i32; bools become the strings ``True`` or
``False`` for ``%s``), which are exactly C's promoted vararg types.

C's ``stdout`` is buffered apart from Python's ``sys.stdout``: a kernel that prints
is launched through ``print_order.flushing``, which flushes Python's buffer before the kernel
runs and C's buffers after it, so the output of Python and of kernels appears in
program order (also when the output is a pipe or a file).
"""

from __future__ import annotations

import ctypes
import hashlib
from functools import cache
from typing import Any

import llvmlite.binding as llvm
from llvmlite import ir

from kdsl.backends.cpu import types as LT
from kdsl.backends.cpu.emitter import Emitter
from kdsl.ir.core import Operation
from kdsl.ir.lowering import LOWERINGS
from kdsl.ir.ops_print import c_format

CPU = LOWERINGS.for_backend("cpu")


@cache
def _libc() -> ctypes.CDLL:
    return ctypes.CDLL(None)


@cache
def _register_printf() -> None:
    """Resolve ``printf`` for JIT code from this process's C library."""
    llvm.add_symbol("printf", ctypes.cast(_libc().printf, ctypes.c_void_p).value)


def _cstring(em: Emitter, text: bytes) -> ir.Value:
    """A pointer to a private NUL-terminated constant holding ``text`` (one per text)."""
    mod = em.state.llmod
    data = bytearray(text + b"\0")
    arr_t = ir.ArrayType(LT.I8, len(data))
    name = f"kd.str.{hashlib.sha1(data).hexdigest()[:16]}"
    g = mod.globals.get(name)
    if g is None:
        g = ir.GlobalVariable(mod, arr_t, name=name)
        g.linkage = "private"
        g.global_constant = True
        g.unnamed_addr = True
        g.initializer = ir.Constant(arr_t, data)
    return em.b.gep(g, [ir.Constant(LT.I32, 0), ir.Constant(LT.I32, 0)], inbounds=True)


def _print(em: Emitter, op: Operation) -> None:
    fnty = ir.FunctionType(LT.I32, [ir.PointerType(LT.I8)], var_arg=True)
    printf = em.state.declare("printf", fnty)
    args: list[Any] = [_cstring(em, c_format(op.attrs["format"]).encode())]
    for v in op.operands:
        x = em.get(v)
        if v.type.is_bool:  # %s of a bool: its word
            x = em.b.select(x, _cstring(em, b"True"), _cstring(em, b"False"))
        args.append(x)
    em.b.call(printf, args)


CPU.register("kd.print", _print)

# Registered on import, before any kernel object (built now or loaded from the kernel
# cache) that calls printf is linked.
_register_printf()
