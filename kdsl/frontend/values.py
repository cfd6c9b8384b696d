"""Compile-time values and the typing of Python literals (Warp's weak literals).

While lowering, an expression gives one of:

- an IR ``Value`` (a runtime value of a fixed type);
- a Python ``int``/``float``/``bool``: a *weak* literal, typed by the value next to
  it (an int literal beside an f32 becomes f32; alone, int is i32 and float f32);
- a ``tuple`` of those (``tid()`` in several dims, a function's several results);
- any other Python object (a module, a builtin, a type, a ``@func``): compile-time.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from kdsl.ir import Value
from kdsl.ir.types import BOOL, F32, I32, MatrixType, ScalarType, Type, VectorType
from kdsl.types import type_of

WEAK = (bool, int, float)


def is_weak(x: Any) -> bool:
    """True for a Python literal still waiting for a type."""
    return isinstance(x, WEAK) and not isinstance(x, np.generic)


def default_type(x: bool | int | float) -> ScalarType:
    """The type a lone literal takes: bool, i32 or f32 (never f64)."""
    if isinstance(x, bool):
        return BOOL
    if isinstance(x, int):
        return I32
    return F32


def literal_fits(x: bool | int | float, t: ScalarType) -> str | None:
    """None when literal ``x`` may take type ``t``, else why not."""
    if isinstance(x, bool):
        return None if t.is_bool else f"a bool literal cannot be used as {t}"
    if t.is_bool:
        return f"a number literal cannot be used as a bool ({x!r})"
    if isinstance(x, float) and t.is_int:
        return (
            f"the float literal {x!r} cannot be combined with an {t} value; "
            f"write an int literal or cast the value with float(...)"
        )
    return None


def describe(x: Any) -> str:
    """A short user-facing name of what an expression gave."""
    if isinstance(x, Value):
        return f"a value of type {x.type}"
    if is_weak(x):
        return f"the literal {x!r}"
    if isinstance(x, tuple):
        return f"a tuple of {len(x)} values"
    if isinstance(x, str):
        return "a string"
    if isinstance(x, list | dict | set):
        return f"a Python {type(x).__name__}"
    name = getattr(x, "__name__", None) or type(x).__name__
    return f"the Python object {name!r}"


def named_type(x: Any) -> Type | None:
    """The IR type ``x`` names (an IR type, or a dtype ``type_of`` knows), or None."""
    if isinstance(x, Type):
        return x
    try:
        return type_of(x)
    except TypeError:
        return None


def is_composite(t: Type) -> bool:
    return isinstance(t, VectorType | MatrixType)


class ShapeOf:
    """``arr.shape``: only good for indexing with a constant (``arr.shape[0]``)."""

    def __init__(self, array: Value) -> None:
        self.array = array


def is_hashable(x: Any) -> bool:
    """True if ``x`` can be a dict key (a Python object a kernel names may be a list)."""
    try:
        hash(x)
    except TypeError:
        return False
    return True
