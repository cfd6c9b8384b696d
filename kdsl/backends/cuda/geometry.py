"""Launch geometry of a cuda kernel: which entry (general or fast) and its grid and block.

``fast_geometry`` applies the launch-time tests of ``variants`` (32-bit offsets fit,
read-only arrays disjoint from written ones, an n-d grid within CUDA's limits) to the
arguments of one launch; ``linear_geometry`` is the general entry's grid.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any

from kdsl.backends.cuda.names import BLOCK
from kdsl.backends.cuda.variants import FastPlan

#: The largest byte offset (and span) a 32-bit offset holds.
INT32_MAX = 2**31 - 1
#: CUDA's limit on ``gridDim.y`` and ``gridDim.z``.
GRID_YZ_MAX = 65535

Geometry = tuple[tuple[int, int, int], tuple[int, int, int]]


def extent(shape: Sequence[int], strides: Sequence[int]) -> tuple[int, int] | None:
    """(lowest, highest) byte offset of an element of an array with ``shape`` and byte
    ``strides`` (element starts), or None when it is empty."""
    lo = hi = 0
    for n, s in zip(shape, strides):
        if n == 0:
            return None
        if s < 0:
            lo += s * (n - 1)
        else:
            hi += s * (n - 1)
    return lo, hi


def offsets_fit(shape: Sequence[int], strides: Sequence[int]) -> bool:
    """True when every in-bounds element's byte offset, and each partial sum of it,
    fits in a 32-bit ``int``: the extents ``|stride| * (n - 1)`` sum to at most
    ``INT32_MAX`` (an empty array has no element to reach)."""
    span = extent(shape, strides)
    return span is None or span[1] - span[0] <= INT32_MAX


def byte_range(array: Any, ndim: int, item: int) -> tuple[int, int] | None:
    """[start, end) byte addresses of the ``item``-byte elements of a CuPy ``array``
    (its first ``ndim`` dims), or None when it is empty."""
    span = extent(array.shape[:ndim], array.strides[:ndim])
    if span is None:
        return None
    ptr = int(array.data.ptr)
    return ptr + span[0], ptr + span[1] + item


def disjoint(a: tuple[int, int] | None, b: tuple[int, int] | None) -> bool:
    """True when byte ranges ``a`` and ``b`` (``byte_range``) share no byte."""
    if a is None or b is None:
        return True
    return a[1] <= b[0] or b[1] <= a[0]


def linear_geometry(total: int) -> Geometry:
    """(grid, block) of the general entry: ``total`` threads in 256-thread blocks."""
    return ((total + BLOCK - 1) // BLOCK, 1, 1), (BLOCK, 1, 1)


@functools.lru_cache(maxsize=256)
def nd_geometry(dims: tuple[int, ...]) -> Geometry | None:
    """(grid, block) of an n-d grid over ``dims`` (the last dim along x), or None when
    it needs more than ``GRID_YZ_MAX`` blocks in y or z. Block extents are powers of
    two, the innermost first, ``BLOCK`` threads at most (fewer for small grids).
    Cached: a simulation launches the same shapes again and again."""
    block, grid, left = [], [], BLOCK
    for d in reversed(dims):
        b = 1
        while b < d and b < left:
            b *= 2
        block.append(b)
        grid.append((d + b - 1) // b)
        left //= b
    if any(g > GRID_YZ_MAX for g in grid[1:]):
        return None
    pad = [1] * (3 - len(dims))
    return (grid[0], *grid[1:], *pad), (block[0], *block[1:], *pad)  # type: ignore[return-value]


def fast_geometry(
    plan: FastPlan, args: Sequence[Any], dims: Sequence[int], total: int
) -> Geometry | None:
    """(grid, block) to launch the fast entry of ``plan`` on ``args`` (CuPy arrays at
    the array positions) over ``dims`` (``total`` threads), or None where only the
    general entry is exact (see ``variants``): one pass over the arrays (this runs
    per launch; 1-d arrays inline) applying ``offsets_fit``, then ``disjoint`` to the
    ``byte_range`` of each read-only array against each written one."""
    read: list[tuple[int, int]] = []
    written: list[tuple[int, int]] = []
    for i, nd, item, role in plan.checks:
        a = args[i]
        if nd == 1:
            n = a.shape[0]
            if n == 0:
                continue
            ext = a.strides[0] * (n - 1)
            lo, hi = (ext, 0) if ext < 0 else (0, ext)
        else:
            span = extent(a.shape[:nd], a.strides[:nd])
            if span is None:
                continue
            lo, hi = span
        if hi - lo > INT32_MAX:
            return None
        if role:
            ptr = a.data.ptr
            (read if role == 1 else written).append((ptr + lo, ptr + hi + item))
    for r in read:
        for w in written:
            if r[0] < w[1] and w[0] < r[1]:  # not disjoint(r, w), inline
                return None
    if plan.grid_nd:
        return nd_geometry(tuple(dims)) if len(dims) == plan.grid_nd else None
    return linear_geometry(total)
