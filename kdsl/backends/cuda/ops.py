"""The cuda backend's lowering table: IR op name -> lowering function.

Each dialect's lowerings live in their own module; this joins them. An op
missing here is reported as a capability error naming the op.
"""

from __future__ import annotations

from kdsl.backends.cuda import arith, checks, control, mathops, memory, printing, vector
from kdsl.backends.cuda.emitter import Lowering

TABLE: dict[str, Lowering] = {
    **arith.TABLE,
    **mathops.TABLE,
    **vector.TABLE,
    **memory.TABLE,
    **control.TABLE,
    **checks.TABLE,
    **printing.TABLE,
}
