"""One definition, one overload per float dtype: the pattern of the geometry library.

kdsl overloads are picked by exact argument types, so a function over quaternions
needs one overload for each of ``quatf``, ``quatd`` and ``quath``. Rather than
writing each function three times, a module writes a *factory*: a Python function
that takes a scalar class (``float32``...) and defines its ``@kdsl.func`` functions
with annotations built from it. Every call of the factory adds one overload to the
same ``Function`` objects (``kdsl.func`` keys functions by qualified name), so
``define_float_overloads`` runs it once per dtype and returns those functions.
A factory's module must not use ``from __future__ import annotations``: the
annotations must be the per-dtype classes, evaluated when each overload is defined.

float32 goes first: a call whose arguments are all literals (``quat_rpy(0.1, 0.2,
0.3)``) matches every overload equally well and takes the first one, float32,
which is what Warp does.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from kdsl.frontend.kernel import Function
from kdsl.types import float16, float32, float64

__all__: list[str] = []

#: The scalar classes every geometry function is defined for, float32 first.
FLOAT_DTYPES: tuple[type, ...] = (float32, float64, float16)


def functions_in(scope: Mapping[str, Any]) -> dict[str, Function]:
    """The ``@kdsl.func`` functions of a factory's ``locals()``, by name."""
    return {name: f for name, f in scope.items() if isinstance(f, Function)}


def define_float_overloads(
    factory: Callable[[type], Mapping[str, Function]],
) -> dict[str, Function]:
    """Run ``factory(dtype)`` for each of ``FLOAT_DTYPES``; the functions it defines."""
    out: dict[str, Function] = {}
    for dtype in FLOAT_DTYPES:
        out.update(factory(dtype))
    return out
