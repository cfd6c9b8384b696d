"""The cpu backend's lowering table, ``TABLE``: IR op name -> lowering function.

Importing this module imports every cpu lowering module, each of which registers its
rules in ``kdsl.ir.lowering.LOWERINGS`` (which refuses a second lowering of an op);
an op missing from the table is reported as a capability error naming the op.
"""

from __future__ import annotations

from kdsl.backends.cpu import (
    arith,
    checks,
    control,
    local,
    mathops,
    memory,
    prefetch,  # kd.prefetch's lowering
    printing,
    target,  # kd.target_has's lowering
    vector,
)
from kdsl.backends.cpu import pointer as array_from_ptr  # kd.array_from_ptr's lowering
from kdsl.backends.cpu.emitter import Lowering
from kdsl.ir.lowering import LOWERINGS

TABLE: dict[str, Lowering] = LOWERINGS.table("cpu")

__all__ = [
    "TABLE",
    "arith",
    "checks",
    "control",
    "local",
    "mathops",
    "array_from_ptr",
    "memory",
    "prefetch",
    "printing",
    "target",
    "vector",
]
