"""The kernel-language builtins: ``wp.sin``, ``wp.dot``, ``wp.atomic_add``...

Each ``Builtin`` maps a call in kernel code to IR ops of the catalog (no builtin adds
an op of its own). The builtins are defined in groups, each module with a
``BuiltinTable`` of its own (``kdsl.frontend.builtins_base``):

- ``builtins_core``: the ops' own builtins (math, vector, logic, memory, ``tid``);
- ``builtins_math``: scalar math composed from ops (``clamp``, ``lerp``...);
- ``builtins_linalg``: vector and matrix math (``trace``, ``inverse``, ``vector()``...);
- ``builtins_ops``: the operator-named builtins (``add``, ``bit_and``...), ``reversed``;
- ``builtins_volume``, ``builtins_texture``: the ``dtype=`` volume builtins, ``texture_sample``;
- ``builtins_arrays``: ``view`` (and ``array``, which the runtime maps onto its class);
- ``geometry``: quaternion and transform constructors;
- ``printing``: ``print`` and ``printf``.

This module, and only it, merges those tables, in this order, into ``BUILTINS``
(``api.py`` exports each as an attribute of ``kdsl``) and ``PYTHON_ALIASES`` (Python's
``abs``/``min``/``max``/``len``, ``math``'s functions and the type factories, mapped onto
the same entries); a name that two tables define is an error.
"""

from __future__ import annotations

import builtins as py
from typing import Any

from kdsl.frontend import (
    builtins_arrays,
    builtins_core,
    builtins_linalg,
    builtins_math,
    builtins_ops,
    builtins_records,
    builtins_texture,
    builtins_volume,
    geometry,
    printing,
)
from kdsl.frontend.builtins_base import Builtin, BuiltinTable
from kdsl.ir.types import BOOL, F32, ScalarType

#: The group tables, merged in this order.
TABLES: tuple[BuiltinTable, ...] = (
    builtins_core.TABLE,
    builtins_math.TABLE,
    builtins_linalg.TABLE,
    builtins_ops.TABLE,
    builtins_records.TABLE,
    builtins_volume.TABLE,
    builtins_texture.TABLE,
    builtins_arrays.TABLE,
    geometry.TABLE,
    printing.TABLE,
)


def merge_tables(tables: tuple[BuiltinTable, ...]) -> tuple[dict[str, Builtin], dict[Any, Builtin]]:
    """``(builtins by name, Python aliases)`` of all ``tables``; a name or a Python object
    that two tables define is a ValueError naming both."""
    builtins: dict[str, Builtin] = {}
    aliases: dict[Any, Builtin] = {}
    source: dict[Any, str] = {}
    for table in tables:
        for what, merged, entries in (("builtin", builtins, table.builtins),
                                      ("Python alias", aliases, table.aliases)):  # fmt: skip
            for key, builtin in entries.items():
                if key in merged:
                    raise ValueError(f"{what} {key!r} is defined by both {source[what, key]} "
                                     f"and {table.source}")  # fmt: skip
                merged[key] = builtin
                source[what, key] = table.source
    return builtins, aliases


BUILTINS, PYTHON_ALIASES = merge_tables(TABLES)


def register_host_alias(python: Any, builtin: Builtin) -> None:
    """In kernels, calling the host function ``python`` calls ``builtin``.

    For names a higher layer defines with a host meaning of their own (the runtime's
    ``zeros`` allocates an array, in kernels it makes a local array): that layer hands
    the function down once. Registering another builtin for the same object is an error.
    """
    old = PYTHON_ALIASES.get(python)
    if old is not None and old is not builtin:
        raise ValueError(f"{python!r} already means the builtin {old.name!r} in kernels")
    PYTHON_ALIASES[python] = builtin


#: Python types usable as casts: float -> f32, int -> i32, bool -> bool.
PYTHON_CASTS: dict[Any, ScalarType] = {py.float: F32, py.int: ScalarType("int", 32), py.bool: BOOL}
