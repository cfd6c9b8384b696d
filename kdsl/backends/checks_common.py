"""The debug-mode error record every compiled backend shares, and its messages.

A kernel compiled in debug mode (or with ``verify_fp``) gets a pointer to an error
record of ``RECORD_LEN`` 64-bit words, zeroed before the launch:

=========  ==========================================================
word       meaning
=========  ==========================================================
0          site + 1 of the first failed bounds (or record) check (0: none failed)
1          its thread's linear index (-1 inside a called function)
2..5       its indices (sign-extended), 6..9 the array's shape (a record check: its id)
10         site + 1 of the first failed finite check (0: none failed)
11         its thread's linear index
12         1 for NaN, 2 for Inf
=========  ==========================================================

A failing check claims its slot with a compare-and-swap from 0, so only the first
failure writes the rest. ``raise_for_record`` turns a record (read back after the
launch) into the ``KdslRuntimeError`` the user sees, with the same text on every
backend.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from kdsl.errors import KdslRuntimeError
from kdsl.ir.ops_debug import Site, bounds_message, fp_message, record_message

RECORD_LEN = 16
BOUNDS, BOUNDS_TID, BOUNDS_IDX, BOUNDS_SHAPE = 0, 1, 2, 6
FP, FP_TID, FP_KIND = 10, 11, 12
#: Indices and shape words kept per bounds failure.
MAX_NDIM = 4


def new_record() -> np.ndarray:
    """A zeroed error record for one launch (host memory)."""
    return np.zeros(RECORD_LEN, dtype=np.int64)


def raise_for_record(
    record: Sequence[int] | np.ndarray,
    sites: Mapping[int, Site],
    kernel: str,
    symbol: str = "",
    dims: tuple[int, ...] = (),
) -> None:
    """Raise the ``KdslRuntimeError`` a launch's error record describes, if any.

    ``kernel`` is the name for messages, ``symbol`` the kernel's IR symbol (to tell
    checks inside called functions apart), ``dims`` the launch grid (to print an
    n-d thread index). A failed bounds check wins over a NaN/Inf: it is the likelier
    cause of both.
    """
    if record[BOUNDS]:
        site = sites.get(int(record[BOUNDS]) - 1)
        nd = max(1, site.ndim) if site is not None else 1
        idx = [int(x) for x in record[BOUNDS_IDX : BOUNDS_IDX + nd]]
        shape = [int(x) for x in record[BOUNDS_SHAPE : BOUNDS_SHAPE + nd]]
        arg = site.arg if site is not None else "array"
        if site is not None and site.op == "kd.check_record":
            msg = record_message(kernel, arg, idx[0] % (1 << 64))
        else:
            msg = bounds_message(kernel, arg, idx, shape)
        tid = int(record[BOUNDS_TID])
    elif record[FP]:
        site = sites.get(int(record[FP]) - 1)
        kind = "NaN" if record[FP_KIND] == 1 else "Inf"
        msg = fp_message(kernel, kind, site.arg if site else "", site.loc if site else None)
        tid = int(record[FP_TID])
    else:
        return
    err = KdslRuntimeError(msg, site.loc if site is not None else None, kernel)
    if site is not None and symbol and site.func != symbol:
        err.add_context(f"in function '{site.func}'")
    if tid >= 0:
        where = tid if len(dims) <= 1 else tuple(int(i) for i in np.unravel_index(tid, dims))
        err.add_context(f"in thread {where} of kernel '{kernel}'")
    raise err
