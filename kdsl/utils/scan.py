"""``array_scan``: inclusive or exclusive prefix sums, component-wise for vectors."""

from __future__ import annotations

import numpy as np

from kdsl.utils import buffers
from kdsl.utils.buffers import UtilsError, check_array, flat_view, on_device, same_device

#: Scalar types a scan accepts (as Warp's).
SCAN_TYPES = (np.int32, np.int64, np.float32, np.float64)


def array_scan(in_array, out_array, inclusive: bool = True) -> None:
    """Write the prefix sums of ``in_array`` into ``out_array`` (Warp's ``array_scan``).

    ``inclusive=True``: ``out[i] = in[0] + ... + in[i]``; otherwise the sum up to
    ``i - 1`` (``out[0] = 0``). Vector elements are summed component-wise. Sums are
    taken in the arrays' own type, in order. ``in_array`` and ``out_array`` may be the
    same array.
    """
    a, out = check_array("in_array", in_array), check_array("out_array", out_array)
    same_device(in_array=a, out_array=out)
    if a.size != out.size:
        raise UtilsError(f"in and out array sizes differ ({a.size} vs {out.size})")
    if a.dtype is not out.dtype:
        raise UtilsError(f"in and out array dtypes differ ({a.dtype} vs {out.dtype})")
    if a.size == 0:
        return
    xp, x = flat_view(a, "in_array")
    _, y = flat_view(out, "out_array")
    if x.dtype.type not in SCAN_TYPES:
        raise UtilsError(f"array_scan supports int32, int64, float32 and float64 elements, "
                         f"not {x.dtype}")  # fmt: skip
    with on_device(a):
        if a.device.is_cuda:
            if inclusive and x.data.ptr != y.data.ptr:
                xp.cumsum(x, axis=0, dtype=x.dtype, out=y)  # CUB's scan, no temporary
            elif inclusive:
                y[...] = xp.cumsum(x, axis=0, dtype=x.dtype)
            else:
                y[1:] = xp.cumsum(x[:-1], axis=0, dtype=x.dtype)
                y[0] = 0
        elif inclusive:
            _host_cumsum(x, y)
        else:
            # In place, the output runs one ahead of the input: the threads of
            # _host_cumsum would read inputs another chunk already overwrote.
            src = x[:-1].copy() if np.shares_memory(x, y) else x[:-1]
            _host_cumsum(src, y[1:])
            y[0] = 0


def _host_cumsum(x: np.ndarray, out: np.ndarray) -> None:
    """``np.cumsum(x, out=out)`` over the host threads: each chunk, then the carries."""
    ranges = buffers.chunks(len(x))

    def part(start: int, end: int) -> None:
        np.cumsum(x[start:end], axis=0, dtype=x.dtype, out=out[start:end])

    buffers.run_parallel(part, ranges)
    if len(ranges) > 1:
        carries = np.cumsum([out[end - 1] for _, end in ranges[:-1]], axis=0, dtype=x.dtype)

        def carry(i: int, _: int) -> None:
            start, end = ranges[i + 1]
            out[start:end] += carries[i]

        buffers.run_parallel(carry, [(i, i) for i in range(len(ranges) - 1)])
