"""``radix_sort_pairs`` and ``segmented_sort_pairs``: stable key-value sorts, as Warp's.

Keys order as a radix sort orders them: integers by value; floats by their bits
made monotone, so ``-0.0`` sorts before ``+0.0`` and NaNs with the sign bit set come
first, the others last (Warp's and CUB's order). Equal keys keep their order. On a
CUDA device the sort is CuPy's (CUB's radix sort); on the CPU the keys are split over
the host's cores, sorted there and merged.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from kdsl.runtime.array import array
from kdsl.types import uint32, uint64
from kdsl.utils.buffers import (
    UtilsError,
    check_array,
    chunks,
    device_buffer,
    flat_view,
    on_device,
    run_parallel,
    same_device,
)

_UNSIGNED = {4: np.uint32, 8: np.uint64}


def radix_order(xp: Any, keys: Any) -> Any:
    """``keys`` as unsigned integers whose order is the radix sort's order of ``keys``."""
    kind, size = keys.dtype.kind, keys.dtype.itemsize
    if kind not in "iuf" or size not in _UNSIGNED:
        raise UtilsError(f"sort keys must be int32, uint32, float32, int64, uint64 or float64, "
                         f"not {keys.dtype}")  # fmt: skip
    u = keys.view(_UNSIGNED[size])
    top = _UNSIGNED[size](1 << (8 * size - 1))
    if kind == "u":
        return u
    if kind == "i":
        return u ^ top
    negative = (u & top) != 0
    return xp.where(negative, ~u, u | top)


def radix_sort_pairs(keys, values, count: int, begin_bit: int = 0, end_bit: int | None = None):
    """Sort ``keys[:count]`` stably in place, moving ``values[:count]`` with them.

    Only key bits ``[begin_bit, end_bit)`` (of the radix order, see the module
    docstring) decide the order. As in Warp, both arrays must hold ``2 * count``
    elements (the second half is scratch space) and values must be 4 or 8 bytes wide.
    """
    k, v = check_array("keys", keys), check_array("values", values)
    same_device(keys=k, values=v)
    count = _count(count)
    if count == 0:
        return
    if k.size < 2 * count or v.size < 2 * count:
        raise UtilsError("keys and values must hold at least 2 * count elements")
    xp, kb = flat_view(k, "keys")
    _, vb = flat_view(v, "values")
    if kb.ndim != 1 or vb.ndim != 1 or vb.dtype.itemsize not in (4, 8):
        raise UtilsError(f"radix_sort_pairs sorts scalar keys with 4- or 8-byte values, not "
                         f"{kb.dtype} keys with {vb.dtype} values")  # fmt: skip
    bits = 8 * kb.dtype.itemsize
    end_bit = bits if end_bit is None else end_bit
    if not 0 <= begin_bit <= end_bit <= bits:
        raise UtilsError(f"need 0 <= begin_bit <= end_bit <= {bits}, got {begin_bit}, {end_bit}")
    with on_device(k):
        order_key = radix_order(xp, kb[:count])
        if (begin_bit, end_bit) != (0, bits):
            mask = (1 << (end_bit - begin_bit)) - 1
            if begin_bit:  # each operation is a kernel on a GPU: no shift by zero
                order_key = order_key >> order_key.dtype.type(begin_bit)
            order_key = order_key & order_key.dtype.type(mask)
            if end_bit - begin_bit <= 32 < bits:  # half the radix passes on 32-bit keys
                order_key = order_key.astype(xp.uint32)
        perm = _argsort(xp, order_key, k.device.is_cuda)
        kb[:count] = kb[:count][perm]
        vb[:count] = vb[:count][perm]


class SortKeys:
    """A prepared in-place ascending sort of unsigned integer keys (a contiguous 1-d
    uint32 or uint64 array) sorted again and again (a BVH build's Morton keys, each
    made unique by its position in its low bits): the checks and the buffer view are made
    once, each call is one sort on the device (CuPy's, CUB's radix sort, on a GPU;
    NumPy's on the CPU), no copies. The sort is not stable: equal keys are equal."""

    __slots__ = ("_keys", "_owner")

    def __init__(self, keys: array) -> None:
        k = check_array("keys", keys)
        if k.ndim != 1 or not k.is_contiguous or k.dtype not in (uint32, uint64):
            raise UtilsError(f"SortKeys sorts a contiguous 1-d uint32 or uint64 array, not "
                             f"{k.dtype} of shape {k.shape}")  # fmt: skip
        self._owner = k
        self._keys = device_buffer(k)[1]

    def __call__(self) -> None:
        """Sort the keys in place."""
        with on_device(self._owner):
            self._keys.sort()


def segmented_sort_pairs(keys, values, count: int, segment_start_indices,
                         segment_end_indices=None) -> None:  # fmt: skip
    """Sort each segment of ``keys[:count]`` stably in place, moving ``values`` along.

    Segment ``s`` is ``[start[s], end[s])``; without ``segment_end_indices``, adjacent
    starts delimit the segments (n starts give n - 1 segments). Ranges must satisfy
    ``0 <= start <= end <= count`` and not overlap (checked: a ``UtilsError``
    otherwise). Elements outside every segment are not moved.
    """
    k, v = check_array("keys", keys), check_array("values", values)
    starts = check_array("segment_start_indices", segment_start_indices)
    ends = None if segment_end_indices is None else check_array(
        "segment_end_indices", segment_end_indices)  # fmt: skip
    same_device(keys=k, values=v, segment_start_indices=starts, segment_end_indices=ends)
    count = _count(count)
    if k.size < 2 * count or v.size < 2 * count:
        raise UtilsError("keys and values must hold at least 2 * count elements")
    lo, hi = _segments(starts, ends, count)
    if count == 0 or len(lo) == 0:
        return
    xp, kb = flat_view(k, "keys")
    _, vb = flat_view(v, "values")
    lengths = hi - lo
    seg = np.repeat(np.arange(len(lo), dtype=np.uint64), lengths)
    # The positions inside the segments, segment by segment.
    inside = np.arange(len(seg)) + np.repeat(lo - (np.cumsum(lengths) - lengths), lengths)
    gpu = k.device.is_cuda
    with on_device(k):
        idx = xp.asarray(inside)
        by_key = _argsort(xp, radix_order(xp, kb[idx]), gpu)
        perm = by_key[_argsort(xp, xp.asarray(seg)[by_key], gpu)]  # stable: keys within segments
        kb[idx] = kb[idx][perm]
        vb[idx] = vb[idx][perm]


def _count(count: Any) -> int:
    if isinstance(count, bool) or not isinstance(count, int | np.integer):
        raise UtilsError(f"count must be an int, got {count!r}")
    if not 0 <= count <= 2**31 - 1:
        raise UtilsError(f"count must be in [0, 2**31 - 1], got {count}")
    return int(count)


def _segments(starts: Any, ends: Any, count: int) -> tuple[np.ndarray, np.ndarray]:
    """The segments' (start, end) arrays on the host, checked."""
    s = starts.numpy().astype(np.int64).ravel()
    if ends is None:
        lo, hi = s[:-1], s[1:]
    else:
        e = ends.numpy().astype(np.int64).ravel()
        if len(e) != len(s):
            raise UtilsError(f"{len(s)} segment starts but {len(e)} segment ends")
        lo, hi = s, e
    bad = np.nonzero((lo < 0) | (hi < lo) | (hi > count))[0]
    if len(bad):
        i = int(bad[0])
        raise UtilsError(f"segment {i} is [{lo[i]}, {hi[i]}), outside 0 <= start <= end <= "
                         f"count ({count})")  # fmt: skip
    order = np.argsort(lo, kind="stable")
    if np.any(lo[order][1:] < hi[order][:-1]):
        raise UtilsError("segments overlap")
    return lo, hi


def _argsort(xp: Any, keys: Any, on_gpu: bool) -> Any:
    """The stable sorting permutation of ``keys`` (unsigned integers)."""
    if on_gpu:
        return xp.argsort(keys)  # CuPy: CUB's radix sort, stable
    packed = _argsort_packed(keys)
    if packed is not None:
        return packed
    ranges = chunks(len(keys))
    runs = run_parallel(lambda a, b: a + np.argsort(keys[a:b], kind="stable"), ranges)
    while len(runs) > 1:  # merge neighbours, pairs of runs at a time on the pool
        pairs = [(i, i + 1) for i in range(0, len(runs) - 1, 2)]
        merged = run_parallel(lambda i, j, runs=runs: _merge(keys, runs[i], runs[j]), pairs)
        runs = merged + ([runs[-1]] if len(runs) % 2 else [])
    return runs[0]


def _argsort_packed(keys: np.ndarray) -> np.ndarray | None:
    """The stable sorting permutation of ``keys`` by one plain sort of each key with its
    position in the bits below it (all distinct, so any sort is stable), or None when key
    and position do not fit in 64 bits. NumPy's sort of 64-bit integers is several times
    faster than its stable sort (a merge sort beyond 16-bit keys): Morton codes, cell
    indices and other small keys take this path."""
    n = len(keys)
    if n == 0:
        return np.zeros(0, np.intp)
    index_bits = max(1, (n - 1).bit_length())
    if int(keys.max()).bit_length() + index_bits > 64:
        return None
    packed = keys.astype(np.uint64) << np.uint64(index_bits)
    packed |= np.arange(n, dtype=np.uint64)
    packed.sort()
    packed &= np.uint64((1 << index_bits) - 1)
    return packed.astype(np.intp)


def _merge(keys: np.ndarray, left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """The stable merge of two sorted index runs (left's elements first among equals)."""
    lk, rk = keys[left], keys[right]
    out = np.empty(len(left) + len(right), left.dtype)
    out[np.arange(len(left)) + np.searchsorted(rk, lk, side="left")] = left
    out[np.arange(len(right)) + np.searchsorted(lk, rk, side="right")] = right
    return out
