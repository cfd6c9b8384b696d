"""The cuda backend's lowering table: IR op name -> lowering function.

Each dialect's lowerings live in their own module and register there, in the
lowering registry (``kdsl.ir.lowering``), which refuses a second lowering of an
op; importing this module imports them all. ``TABLE`` is the registry's dispatch
table for ``cuda``: an op missing from it is reported as a capability error naming
the op.
"""

from __future__ import annotations

from kdsl.backends.cuda import arith, checks, control, mathops, memory, printing, vector
from kdsl.backends.cuda.emitter import Lowering
from kdsl.ir.lowering import LOWERINGS

CUDA = LOWERINGS.for_backend("cuda")

# NOTE: ``checks`` keeps a table of its own; its entries go through the registry here.
for _name, _fn in checks.TABLE.items():
    CUDA.register(_name, _fn)

TABLE: dict[str, Lowering] = LOWERINGS.table("cuda")

__all__ = ["TABLE", "arith", "control", "mathops", "memory", "printing", "vector"]
