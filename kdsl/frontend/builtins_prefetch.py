"""``prefetch(arr, i...)`` for library code (IR: ``kd.prefetch``, ``kdsl.ir.ops_prefetch``).

Not a user builtin (no table lists it, docs/builtins.md does not show it): the standard
library calls the ``Builtin`` object itself where it knows an element's address well
before it reads it (the CPU's 4-wide mesh walk, ``kdsl.stdlib.mesh_wide``).
"""

from __future__ import annotations

from typing import Any

from kdsl.errors import KdslTypeError
from kdsl.frontend.builtins_base import Builtin
from kdsl.ir.types import I32, ArrayType


def _prefetch(em, args: list[Any], node, **kw: Any) -> None:
    if kw:
        raise em.error(KdslTypeError, "prefetch() takes no keyword arguments", node)
    arr = em.value(args[0], node)
    if not isinstance(arr.type, ArrayType):
        raise em.error(KdslTypeError, f"prefetch() needs an array first, not {arr.type}", node)
    if len(args) - 1 != arr.type.ndim:
        raise em.error(KdslTypeError, f"prefetch() of a {arr.type.ndim}-d array needs "
                       f"{arr.type.ndim} indices, got {len(args) - 1}", node)  # fmt: skip
    idx = [em.value(x, node, want=I32) for x in args[1:]]
    em.b.create("kd.prefetch", [arr, *idx], [], None, loc=em.loc(node))


PREFETCH = Builtin(
    "prefetch",
    _prefetch,
    "``prefetch(arr, i...)``: a hint that the thread will soon read ``arr[i...]`` (the cpu "
    "backend prefetches its cache lines; cuda and the interpreter do nothing).",
    (2, 5),
    "memory",
)

__all__ = ["PREFETCH"]
