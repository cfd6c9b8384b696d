"""What every group of kernel builtins is built from: ``Builtin``, ``BuiltinTable`` and
the argument conversions the lowerings share.

Each group module (``builtins_core``, ``builtins_math``, ``builtins_linalg``,
``geometry``, ``printing``) fills one ``BuiltinTable`` of its own; only
``kdsl.frontend.builtins`` reads the tables, and it merges them into ``BUILTINS``,
refusing a name that two tables define. This module imports none of them, so the
groups and the merge import one way.
"""

from __future__ import annotations

import ast
import builtins as py
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from kdsl.errors import KdslTypeError
from kdsl.frontend import bfloat16
from kdsl.frontend.values import is_weak
from kdsl.ir import Value
from kdsl.ir.types import BF16, F32, ScalarType
from kdsl.types import python_scope

#: ``lower(emitter, args, node)``: emits a builtin's ops for one call.
Lower = Callable[[Any, list[Any], ast.Call], Any]


@dataclass(eq=False, repr=False)
class Builtin:
    """A kernel builtin: ``lower(emitter, args, node)`` emits its ops.

    Compared and hashed by identity: the expression visitor looks builtins up in
    tables keyed by Python objects.
    """

    name: str
    lower: Lower
    #: The builtin's documentation, also its ``__doc__`` (docs/builtins.md shows it).
    doc: str
    #: The fewest and the most positional arguments.
    arity: tuple[int, int]
    #: The group docs/builtins.md lists it under (``math``, ``vector``, ``memory``...).
    group: str
    #: Keyword arguments the builtin accepts (passed to ``lower`` as keywords).
    keywords: tuple[str, ...] = ()
    #: Positions of in-out arguments: a local variable passed there is rebound (the
    #: lowering writes it back), so loops carry it (``kdsl.frontend.inout``).
    inout: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        self.__doc__ = self.doc

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        """In Python scope: the builtin evaluated with its kernel semantics
        (``kdsl.compiler.python_scope``); ``kdsl.sin(0.5)`` is ``np.float32(0.47942555)``."""
        return python_scope(self, args, kwargs)

    def __repr__(self) -> str:
        return f"<kdsl builtin {self.name}>"


class BuiltinTable:
    """The builtins one group module defines, and the Python objects that mean them.

    ``source`` (the module's ``__name__``) names the table in errors. A name defined
    twice in one table is refused here; ``kdsl.frontend.builtins`` refuses a name that
    two tables define.
    """

    def __init__(self, source: str) -> None:
        self.source = source
        #: Builtins by name, in definition order.
        self.builtins: dict[str, Builtin] = {}
        #: Python objects (``abs``, ``math.sin``, type factories) -> the builtin they mean.
        self.aliases: dict[Any, Builtin] = {}

    def add(self, builtin: Builtin) -> Builtin:
        """Add ``builtin``; a name already in this table is an error."""
        if builtin.name in self.builtins:
            raise ValueError(f"builtin {builtin.name!r} is defined twice in {self.source}")
        self.builtins[builtin.name] = builtin
        return builtin

    def define(self, name: str, arity: tuple[int, int], doc: str, group: str,
               keywords: tuple[str, ...] = ()) -> Callable[[Lower], Lower]:  # fmt: skip
        """Decorator: the function is the lowering of a new builtin ``name``."""

        def deco(fn: Lower) -> Lower:
            self.add(Builtin(name, fn, doc, arity, group, keywords))
            return fn

        return deco

    def alias(self, python: Any, builtin: Builtin | str) -> None:
        """In kernels, calling the Python object ``python`` calls ``builtin``.

        ``builtin`` is a Builtin, or the name of one of this table's builtins.
        """
        if python in self.aliases:
            raise ValueError(f"{python!r} is aliased twice in {self.source}")
        self.aliases[python] = self.builtins[builtin] if isinstance(builtin, str) else builtin


def unified(em, args: list[Any], node: ast.AST) -> list[Value]:
    """Arguments typed together: weak literals take the first typed argument's type."""
    typed = next((a for a in args if isinstance(a, Value)), None)
    if typed is None:
        floats = any(isinstance(a, float) for a in args)
        return [em.value(float(a) if floats and not isinstance(a, bool | float) else a, node)
                for a in args]  # fmt: skip
    return [em.coerce_pair(a, typed, node)[0] if is_weak(a) else em.value(a, node) for a in args]


def float_default(em, x: Any, node: ast.AST) -> Value:
    """``x`` as a value, where a lone int literal is a float (``sqrt(2)``), as in Python."""
    if is_weak(x) and not isinstance(x, bool):
        # A float stays the object it is (Python scope compiles with placeholder literals).
        return em.const(x if isinstance(x, float) else float(x), F32, node)
    return em.value(x, node)


def cast(em, t: ScalarType, args: list[Any], node: ast.AST) -> Value:
    """``float32(x)``/``float(x)``/``int(x)``: a conversion (or a typed constant)."""
    if t is BF16:  # bfloat16(x): x rounded to it, as a float32 (a storage type)
        return bfloat16.round_value(em, args[0] if args else 0.0, node)
    if not args:
        return em.zero(t, node)
    x = args[0]
    if is_weak(x):
        if t.is_int and isinstance(x, float):
            x = math.trunc(x)
        elif t.is_float:
            x = float(x)
        elif t.is_bool:
            x = py.bool(x)
        return em.const(x, t, node)
    v = em.value(x, node)
    if not isinstance(v.type, ScalarType):
        raise em.error(KdslTypeError, f"cannot convert a {v.type} to the scalar {t}", node)
    if v.type == t:
        return v
    return em.emit_typed("arith.cast", [v], t, node)
