"""The cpu backend's lowering table: IR op name -> lowering function.

Each dialect's lowerings live in their own module and register there, in the
lowering registry (``kdsl.ir.lowering``), which refuses a second lowering of an
op; importing this module imports them all. ``TABLE`` is the registry's dispatch
table for ``cpu``: an op missing from it is reported as a capability error naming
the op.
"""

from __future__ import annotations

from kdsl.backends.cpu import arith, checks, control, mathops, memory, printing, vector
from kdsl.backends.cpu.emitter import Lowering
from kdsl.ir.lowering import LOWERINGS

CPU = LOWERINGS.for_backend("cpu")

# NOTE: ``checks`` keeps a table of its own; its entries go through the registry here.
for _name, _fn in checks.TABLE.items():
    CPU.register(_name, _fn)

TABLE: dict[str, Lowering] = LOWERINGS.table("cpu")

__all__ = ["TABLE", "arith", "control", "mathops", "memory", "printing", "vector"]
