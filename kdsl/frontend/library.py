"""Library functions the frontend lowers operators to, registered by the standard library.

Some kernel syntax is defined by kdsl code rather than by an IR op: ``q1 * q2`` on
quaternions calls the standard library's ``quat_multiply``, ``t.p`` on a transform
calls ``transform_get_translation``. The standard library sits above the frontend
(it is ``@kdsl.func`` code), so it hands those functions down here once, from
``kdsl.stdlib.api``; the frontend looks them up by name when it compiles such syntax.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from kdsl.errors import KdslError

_FUNCTIONS: dict[str, Any] = {}

#: The names the frontend asks for; ``register_library`` must provide each.
REQUIRED = (
    "quat_multiply",
    "quat_normalize",
    "transform_multiply",
    "transform_get_translation",
    "transform_set_translation_copy",
    "transform_get_rotation",
    "transform_set_rotation_copy",
)


def register_library(functions: Mapping[str, Any]) -> None:
    """Register ``functions`` (name -> ``@kdsl.func``); a name registered twice is an error."""
    for name, fn in functions.items():
        old = _FUNCTIONS.get(name)
        if old is not None and old is not fn:
            raise KdslError(f"library function {name!r} is registered twice")
        _FUNCTIONS[name] = fn


def library_function(name: str) -> Any:
    """The registered library function ``name``."""
    fn = _FUNCTIONS.get(name)
    if fn is None:
        raise KdslError(
            f"the standard library function {name!r} is not registered: import kdsl (which "
            "loads kdsl.stdlib) before compiling kernels"
        )
    return fn


#: Query struct types (IR ``StructType``) -> the ``..._next`` function that advances them,
#: so ``for index in query:`` iterates a geometry query as in Warp.
_QUERY_ITERATORS: dict[Any, Any] = {}


def register_query_iterator(query_type: Any, next_fn: Any) -> None:
    """Let ``for index in q:`` run ``while next_fn(q, index):`` for a ``q`` of ``query_type``
    (a ``@kdsl.struct`` class); ``next_fn(query, index)`` advances both in place."""
    _QUERY_ITERATORS[query_type.__kdsl_type__] = next_fn


def query_iterator(t: Any) -> Any | None:
    """The ``..._next`` function registered for query type ``t``, or None."""
    return _QUERY_ITERATORS.get(t)
