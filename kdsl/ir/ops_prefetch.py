"""``kd.prefetch``: a hint that a thread will soon read one array element.

``kd.prefetch %array, %i...`` asks the hardware to bring the element's cache lines
close (the cpu backend: LLVM's ``llvm.prefetch``, one per 64-byte line the element may
touch, for reading, into all cache levels); it reads and writes nothing a kernel can
see, cannot fault (an index out of range is no error: the hardware drops such a
prefetch), and the cuda backend and the interpreter do nothing for it. Library code
uses it where a load's address is known well before the load, as the CPU's 4-wide
mesh walk (``kdsl.stdlib.mesh_wide``) does for a node's four children: their loads then
miss the cache side by side instead of one after another.

It has no result, so it carries ``WRITES`` (as ``kd.print``) for passes to keep it;
no pass moves loads across ops with effects, so it orders nothing else.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from kdsl.ir.catalog import CATALOG, WRITES
from kdsl.ir.ops_mem import check_access
from kdsl.ir.types import Type


def _rule(ts: Sequence[Type], attrs: dict[str, Any]) -> list[Type]:
    check_access(ts[0], ts[1:], "kd.prefetch takes an array and its indices")
    return []


def _interp(ctx, op, *args) -> None:
    """A hint: nothing to do (and no bounds check: a prefetch never faults)."""
    return None


PREFETCH = CATALOG.define(
    "kd.prefetch",
    "A hint that the thread will soon read element ``i...`` of the array: the cpu "
    "backend prefetches its cache lines (``llvm.prefetch``), cuda and the interpreter "
    "do nothing; no result, no visible effect, never a fault "
    "(``kdsl.ir.ops_prefetch``).",
    traits=frozenset({WRITES}), type_rule=_rule, interp=_interp,
    example="kd.prefetch %0, %1", group="memory",
)  # fmt: skip

__all__ = ["PREFETCH"]
