"""``ChunkSum``: a prepared sum of a float32 array as kdsl kernels, in a fixed order.

A mesh sums its edge lengths at construction and at every refit. CuPy's reduction
costs tens of microseconds of host dispatch, allocates its result from the pool and
cannot join a captured graph; this sum is prepared kernel launches only, over scratch
allocated once: each level adds chunks of ``CHUNK`` consecutive values into one value
per chunk (one thread a chunk, in index order), until one value is left, which the
last level writes to ``out[0]``. The order of the additions depends on the length
alone, so a sum gives the same bits every time on every device (not those of NumPy's
or CuPy's pairwise sums: the rounding differs in the last bits).

A ``guard`` (int32 values on the device) skips the write of ``out[0]`` when any of
them is nonzero, so a sum issued behind a check (a mesh's first bad index and point)
leaves ``out`` as it was when the check found something, without the host waiting for
the check first.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from kdsl.frontend.api import kernel, tid
from kdsl.frontend.api import min as vmin
from kdsl.runtime.alloc import empty
from kdsl.runtime.array import array
from kdsl.runtime.launch import launch
from kdsl.types import float32, int32
from kdsl.utils.buffers import UtilsError, check_array, same_device

#: Values each thread adds per level (64: three levels for 200k values).
CHUNK = 64


@kernel
def _sum_chunks(
    src: array(dtype=float32), n: int32, chunk: int32, guard: array(dtype=int32),
    dst: array(dtype=float32),
):  # fmt: skip
    # Thread t: the sum of src[t * chunk : (t + 1) * chunk] (in order) into dst[t], unless
    # a guard value is nonzero.
    for g in range(guard.shape[0]):
        if guard[g] != 0:
            return
    t = tid()
    s = float32(0.0)
    for i in range(t * chunk, vmin(t * chunk + chunk, n)):
        s += src[i]
    dst[t] = s


def sum_levels(n: int, chunk: int = CHUNK) -> list[int]:
    """The number of values each level of a sum of ``n`` values writes (the last: 1)."""
    sizes = [max(n, 1)]
    while sizes[-1] > 1 or len(sizes) == 1:
        sizes.append(-(-sizes[-1] // chunk))
    return sizes[1:]


def scratch_size(n: int, chunk: int = CHUNK) -> int:
    """The float32 values of scratch a ``ChunkSum`` of ``n`` values needs."""
    return sum(sum_levels(n, chunk)[:-1])


class ChunkSum:
    """A prepared ``out[0] = sum(values)`` (see the module docstring): ``values`` a
    contiguous 1-d float32 array, ``out`` a float32 array of at least one element on its
    device, ``guard`` None or an int32 array there. The launches are prepared once, on
    ``stream`` (a ``kdsl.Stream`` of the device; None: the one current when it is made);
    ``steps`` lists them (for a caller that captures them as a graph). An empty
    ``values`` sums to 0.0. ``scratch``: float32 values on the device for the levels
    before the last (``scratch_size``; allocated when None)."""

    __slots__ = ("steps", "_scratch")

    def __init__(self, values: array, out: array, guard: array | None = None,
                 chunk: int = CHUNK, scratch: array | None = None,
                 stream: Any = None) -> None:  # fmt: skip
        v, o = check_array("values", values), check_array("out", out)
        g = None if guard is None else check_array("guard", guard)
        same_device(values=v, out=o, guard=g)
        if v.ndim != 1 or not v.is_contiguous or v.dtype is not float32:
            raise UtilsError(f"ChunkSum sums a contiguous 1-d float32 array, not {v.dtype} of "
                             f"shape {v.shape}")  # fmt: skip
        if o.ndim != 1 or o.shape[0] < 1 or o.dtype is not float32:
            raise UtilsError(f"ChunkSum writes a float32 array of at least one element, not "
                             f"{o.dtype} of shape {o.shape}")  # fmt: skip
        if g is not None and (g.ndim != 1 or g.dtype is not int32):
            raise UtilsError(f"ChunkSum's guard is a 1-d int32 array, not {g.dtype} of shape "
                             f"{g.shape}")  # fmt: skip
        if not isinstance(chunk, int) or chunk < 2:
            raise UtilsError(f"ChunkSum chunk must be an int of at least 2, not {chunk!r}")
        device = v.device
        sizes = sum_levels(v.shape[0], chunk)
        if scratch is None:  # one block for the levels before the last
            scratch = empty(max(sum(sizes[:-1]), 1), dtype=float32, device=device)
        s = check_array("scratch", scratch)
        same_device(values=v, scratch=s)
        if s.ndim != 1 or s.dtype is not float32 or s.shape[0] < sum(sizes[:-1]):
            raise UtilsError(f"ChunkSum's scratch is {sum(sizes[:-1])} float32 at least, not "
                             f"{s.dtype} of shape {s.shape}")  # fmt: skip
        self._scratch = s
        none = empty(0, dtype=int32, device=device) if g is None else g[:0]
        self.steps: list[Callable[[], None]] = []
        src, n, at = v, v.shape[0], 0
        for k, size in enumerate(sizes):
            last = k == len(sizes) - 1
            dst = o[:1] if last else self._scratch[at : at + size]
            self.steps.append(launch(
                _sum_chunks, dim=size, device=device, record_cmd=True, stream=stream,
                inputs=[src, n, chunk, g if last and g is not None else none, dst],
            ).launch)  # fmt: skip
            src, n, at = dst, size, at + size

    def __call__(self) -> None:
        """Write the sum (unless the guard says otherwise)."""
        for step in self.steps:
            step()
