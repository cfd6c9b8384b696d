"""Compile-time markers usable in kernels: ``kdsl.static`` and ``kdsl.constant``."""

from __future__ import annotations

from typing import Any

import numpy as np


def static(expr: Any) -> Any:
    """Evaluate ``expr`` at compile time, in Python, with the kernel's globals and closure.

    In a kernel, ``wp.static(n * 2)`` becomes a constant; ``for i in
    range(wp.static(n))`` is unrolled. In Python scope it returns ``expr``.
    """
    return expr


def constant(x: Any) -> Any:
    """Mark a module-level constant (a number or a kdsl vector/matrix) for kernels.

    Kernels read module globals at compile time anyway; this checks that ``x`` is a
    value a kernel can use and returns it unchanged.
    """
    ok = isinstance(x, bool | int | float | np.generic) or (
        isinstance(x, np.ndarray) and hasattr(type(x), "__kdsl_type__")
    )
    if not ok:
        raise TypeError(f"kdsl.constant() takes a number or a kdsl vector/matrix, not {x!r}")
    return x
