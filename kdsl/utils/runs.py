"""``runlength_encode``: runs of equal values, as (value, length) pairs."""

from __future__ import annotations

import numpy as np

from kdsl.utils.buffers import UtilsError, check_array, flat_view, on_device, same_device


def runlength_encode(values, run_values, run_lengths, run_count=None, value_count=None):
    """Encode ``values[:value_count]`` (int32) as runs (Warp's ``runlength_encode``).

    ``[1, 1, 1, 2, 2, 3]`` gives ``run_values = [1, 2, 3]``, ``run_lengths = [3, 2, 1]``.
    Returns the number of runs, or, with ``run_count`` (an int32 array), writes it to
    ``run_count[0]`` on the device and returns ``run_count``.
    """
    v = check_array("values", values)
    rv, rl = check_array("run_values", run_values), check_array("run_lengths", run_lengths)
    rc = None if run_count is None else check_array("run_count", run_count)
    same_device(values=v, run_values=rv, run_lengths=rl, run_count=rc)
    n = v.size if value_count is None else int(value_count)
    if not 0 <= n <= v.size:
        raise UtilsError(f"value_count must be in [0, {v.size}], got {value_count}")
    if rv.size < n or rl.size < n:
        raise UtilsError(f"run_values and run_lengths must hold at least value_count ({n}) "
                         "elements")  # fmt: skip
    xp, x = flat_view(v, "values")
    _, out_values = flat_view(rv, "run_values")
    _, out_lengths = flat_view(rl, "run_lengths")
    for name, b in (("values", x), ("run_values", out_values), ("run_lengths", out_lengths)):
        if b.dtype != np.int32 or b.ndim != 1:
            raise UtilsError(f"runlength_encode takes int32 arrays; {name} holds {b.dtype}")
    with on_device(v):
        x = x[:n]
        starts = xp.flatnonzero(xp.concatenate([xp.ones(min(n, 1), bool), x[1:] != x[:-1]]))
        runs = len(starts)
        out_values[:runs] = x[starts]
        out_lengths[:runs] = xp.diff(xp.append(starts, n)).astype(np.int32)
        if rc is None:
            return runs
        _, count_buf = flat_view(rc, "run_count")
        count_buf[0] = runs
    return rc
