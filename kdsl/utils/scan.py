"""``array_scan``: inclusive or exclusive prefix sums, component-wise for vectors."""

from __future__ import annotations

import numpy as np

from kdsl.runtime.array import array
from kdsl.utils import buffers
from kdsl.utils.buffers import (
    UtilsError,
    check_array,
    device_buffer,
    flat_view,
    on_device,
    same_device,
)

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


class ScanInto:
    """A prepared inclusive ``array_scan(values, out)`` for arrays scanned again and again
    (a BVH build's node counts): the checks and the buffer views are made once, each
    call is ``array_scan``'s own operation (one CUB scan on a GPU, the threaded host
    scan on the CPU). ``values`` and ``out`` are distinct contiguous 1-d arrays of one
    scalar dtype of ``SCAN_TYPES`` on one device."""

    __slots__ = ("_gpu", "_out", "_owner", "_values", "_xp")

    def __init__(self, values: array, out: array) -> None:
        a, b = check_array("values", values), check_array("out", out)
        same_device(values=a, out=b)
        for name, x in (("values", a), ("out", b)):
            if x.ndim != 1 or not x.is_contiguous:
                raise UtilsError(f"ScanInto needs contiguous 1-d arrays; {name} has shape "
                                 f"{x.shape}")  # fmt: skip
        self._owner, self._gpu = a, a.device.is_cuda
        self._xp, self._values = device_buffer(a)
        self._out = device_buffer(b)[1]
        if self._values.dtype.type not in SCAN_TYPES or self._values.dtype != self._out.dtype:
            raise UtilsError(f"ScanInto scans int32, int64, float32 or float64 into the same "
                             f"dtype, not {a.dtype} into {b.dtype}")  # fmt: skip
        if a.size != b.size or self._xp.shares_memory(self._values, self._out):
            raise UtilsError("ScanInto needs distinct values and out arrays of one size")

    def __call__(self) -> None:
        """Write the inclusive prefix sums of ``values`` into ``out``."""
        x, y = self._values, self._out
        with on_device(self._owner):
            if self._gpu:
                self._xp.cumsum(x, axis=0, dtype=x.dtype, out=y)
            else:
                _host_cumsum(x, y)


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
