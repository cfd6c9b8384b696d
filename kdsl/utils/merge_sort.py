"""``MergeSortKeys``: an in-place ascending sort of uint64 keys as kdsl kernels.

Written once for every backend, so on a GPU the sort is kernel launches on the
device's stream and nothing else: no host synchronization (CuPy's sort, Thrust's,
waits for the stream at its end: cupy#9126), no call into another library, so a
build that uses it can be captured as one CUDA graph. The sort:

1. ``_sort_chunks``: each thread sorts a chunk of ``chunk`` keys by insertion;
2. ``_merge_runs``, once per doubling of the sorted runs: each thread places one key
   of a pair of runs into the merged run, at its own position in its run plus the
   number of keys of the other run before it (a binary search: keys of the left run
   go before equal keys of the right one, so the sort is stable, which only matters
   for equal keys, and equal keys are equal). Runs ping-pong between the keys and a
   scratch array of as many; the chunk sort writes where an even or odd number of
   merges leaves the result in the keys.

``ceil(log2(n / chunk))`` merges: 16 launches in all for 200k keys in chunks of 8 (on an
H200, chunks of 8, 16 and 32 sorted 200k keys in about 60, 85 and 140 us as a graph).
The merges are two prepared launches, one per direction of the ping-pong, whose run
length is written into their packed arguments before each launch (``Launch``'s
patchable form): a sort made once (a first build) prepares three launches, not one per
merge. (A CUDA launch copies its arguments when it is issued, and a captured one when
it is captured, so a later write never reaches an issued merge.)
"""

from __future__ import annotations

import functools
from collections.abc import Callable

from kdsl.frontend.api import kernel, tid
from kdsl.frontend.api import min as vmin
from kdsl.runtime.array import array
from kdsl.runtime.launch import Launch, launch
from kdsl.types import int32, uint64
from kdsl.utils.buffers import UtilsError, check_array

#: Keys each thread of the first step sorts by insertion (8: fastest on an H200).
CHUNK = 8
#: The most keys: twice a run must fit an int32.
MAX_KEYS = 2**30


@kernel
def _sort_chunks(src: array(dtype=uint64), dst: array(dtype=uint64), n: int32, chunk: int32):
    # Thread t: keys [t * chunk, t * chunk + chunk) of ``src``, sorted into the same
    # places of ``dst`` (which may be ``src``: key i is read before any write reaches i).
    a = tid() * chunk
    for i in range(a, vmin(a + chunk, n)):
        k = src[i]
        j = i
        while j > a:
            p = dst[j - 1]
            if p <= k:
                break
            dst[j] = p
            j -= 1
        dst[j] = k


@kernel
def _merge_runs(src: array(dtype=uint64), dst: array(dtype=uint64), n: int32, run: int32):
    # Key i of ``src`` (sorted runs of ``run`` keys) into the merge of its pair of runs.
    i = tid()
    k = src[i]
    base = (i // (2 * run)) * (2 * run)
    mid = vmin(base + run, n)
    end = vmin(base + 2 * run, n)
    if i < mid:  # the left run: the right run's keys below k go first
        lo = mid
        hi = end
        while lo < hi:
            m = (lo + hi) >> 1
            if src[m] < k:
                lo = m + 1
            else:
                hi = m
        dst[i + lo - mid] = k
    else:  # the right run: the left run's keys up to k go first
        lo = base
        hi = mid
        while lo < hi:
            m = (lo + hi) >> 1
            if src[m] <= k:
                lo = m + 1
            else:
                hi = m
        dst[i - mid + lo] = k


def merge_passes(n: int, chunk: int = CHUNK) -> int:
    """The number of merges that sort ``n`` keys from sorted chunks of ``chunk``."""
    passes, run = 0, chunk
    while run < n:
        run, passes = 2 * run, passes + 1
    return passes


class MergeSortKeys:
    """A prepared in-place ascending sort of ``keys`` (a contiguous 1-d uint64 array)
    with ``scratch`` (another of as many, on the same device), sorted again and again:
    the launches are prepared once, each call runs them on the stream current when it
    was made. ``steps`` lists them (for a caller that captures them as a graph)."""

    __slots__ = ("steps",)

    def __init__(self, keys: array, scratch: array, chunk: int = CHUNK) -> None:
        for name, a in (("keys", keys), ("scratch", scratch)):
            a = check_array(name, a)
            if a.ndim != 1 or not a.is_contiguous or a.dtype is not uint64:
                raise UtilsError(f"MergeSortKeys sorts a contiguous 1-d uint64 array with "
                                 f"scratch of the same, not {name} of {a.dtype} and shape "
                                 f"{a.shape}")  # fmt: skip
        n = keys.shape[0]
        if scratch.shape[0] != n or scratch.device != keys.device:
            raise UtilsError(f"MergeSortKeys needs scratch of {n} keys on {keys.device}, not "
                             f"{scratch.shape[0]} on {scratch.device}")  # fmt: skip
        if n > MAX_KEYS:
            raise UtilsError(f"MergeSortKeys sorts at most {MAX_KEYS} keys, not {n}")
        if not isinstance(chunk, int) or chunk < 1:
            raise UtilsError(f"MergeSortKeys chunk must be a positive int, not {chunk!r}")
        device = keys.device
        passes = merge_passes(n, chunk)
        src = keys if passes % 2 == 0 else scratch  # where the chunks go: the merges end in keys

        def prepared(kernel_, dim: int, inputs: list) -> Callable[[], None]:
            return launch(kernel_, dim=dim, device=device, inputs=inputs, record_cmd=True).launch

        self.steps: list[Callable[[], None]] = []
        if n < 2:
            return
        self.steps.append(prepared(_sort_chunks, -(-n // chunk), [keys, src, n, chunk]))
        merges: dict[bool, Launch] = {}  # by direction: from the keys or from the scratch
        run = chunk
        for _ in range(passes):
            dst = scratch if src is keys else keys
            merge = merges.get(src is keys)
            if merge is None:
                merge = merges[src is keys] = launch(
                    _merge_runs, dim=n, device=device, inputs=[src, dst, n, run], record_cmd=True
                )  # fmt: skip
            self.steps.append(functools.partial(_merge_pass, merge, run))
            src, run = dst, 2 * run

    def __call__(self) -> None:
        """Sort the keys in place."""
        for step in self.steps:
            step()


def _merge_pass(merge: Launch, run: int) -> None:
    """One merge of runs of ``run`` keys: ``merge`` with its run length set, launched."""
    merge.set_param_at_index(3, run)
    merge.launch()
