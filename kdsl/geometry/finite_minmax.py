"""Componentwise minimum and maximum of vec3 known to be finite, for box bounds.

kdsl's ``min``/``max`` order -0.0 before 0.0 and pass a NaN over (IEEE 754-2019
``minimumNumber``): on x86 without AVX10.2 LLVM lowers each to about six instructions
(a sign blend, the min, an unordered compare and a blend). Bounds over checked points
need neither property (a box's lower zero is as good with either sign), and a compare
with a select is one ``vminss``/``vmaxss``: the CPU mesh refit's node bounds took a
third of the time (docs/performance.md, "CPU refit and build, session 12"). Only for
finite values: with a NaN these return whichever operand the compare picks.
"""

from __future__ import annotations

from kdsl.frontend.api import func, where
from kdsl.types import vec3


@func
def low3(a: vec3, b: vec3) -> vec3:
    """The componentwise minimum of finite ``a`` and ``b`` (a compare and a select each)."""
    return vec3(where(a[0] < b[0], a[0], b[0]), where(a[1] < b[1], a[1], b[1]),
                where(a[2] < b[2], a[2], b[2]))  # fmt: skip


@func
def high3(a: vec3, b: vec3) -> vec3:
    """The componentwise maximum of finite ``a`` and ``b`` (a compare and a select each)."""
    return vec3(where(a[0] > b[0], a[0], b[0]), where(a[1] > b[1], a[1], b[1]),
                where(a[2] > b[2], a[2], b[2]))  # fmt: skip
