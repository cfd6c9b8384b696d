"""The two builds of a ``kdsl.HashGrid``'s tables, both kdsl kernels on the grid's device
with no read back to the host, both giving the same point order (points sorted by
bucket, stably: a bucket's points in their original order) and bucket ranges.

``SortBuild`` (every device's): two kernels around one sort.

1. ``_bucket_keys``: each point's key, its bucket in the high 32 bits and its index in
   the low 32 (unique keys, so any sort is stable), and, first, the bucket of the
   previous build's ``i``-th key emptied in the cell tables (those buckets are the
   tables' only nonzero entries);
2. a sort of the keys in place (``kdsl.utils.sort.SortKeys``: NumPy's sort on the CPU;
   on a GPU the kdsl merge sort, ``kdsl.utils.merge_sort``: launches only, no host
   synchronization, so from a rebuild on the build replays as one CUDA graph);
3. ``_bucket_ranges``: the point order (the keys' low halves) and each bucket's range of
   it, found by comparing sorted neighbours (empty buckets: ``[0, 0)``).

Its work grows with the point count only, never with the cell count (a 128^3 grid has
2M cells, ten times a 200k-point build's points): the tables are zeroed once, when
allocated, and then only the previous build's buckets are emptied.

``CountBuild`` (a GPU's until the kdsl merge sort; tests try it everywhere): a counting
sort by bucket, all kdsl launches (ten, prepared), written when the sort of keys needed
CuPy's radix sort (86 of a rebuild's 112 us of host time on an H200) and CuPy's scan
would cost as much (114 us for 2M counts). Its work grows with the cell count.

1. ``_count_points``: each point's bucket, and its slot in it from an atomic count;
2. an inclusive scan of the counts into ``offsets[1:]`` (``offsets[0]`` stays 0;
   ``_Scan``: seven launches for 2M counts), which is both tables at once: bucket ``c``
   is ``[offsets[c], offsets[c + 1])`` (empty buckets: ``[p, p)``);
3. ``_count_scatter``: each point into its bucket's range at its slot, and the counts
   back to zero for the next build;
4. ``_count_order``: the atomic slots come in any order, so each point's final place is
   its bucket's start plus the number of the bucket's points with a smaller index. That
   costs the square of each bucket's size, as one query of the points does at least
   (each point's query visits its own bucket), so no input makes the build cost more
   than one query pass over the same points.

Both keep their buffers between builds, grow them only when the point count exceeds
what they hold, and prepare their launches once per points array and count. On a GPU
their launches are captured as one CUDA graph at the second build of the same points
array, count and radius, and replayed from then on (one graph launch of host time
instead of one per kernel: ``_Steps``, ``graph_steps``).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import Any

import numpy as np

from kdsl.frontend.api import atomic_add, kernel, tid
from kdsl.frontend.api import min as vmin
from kdsl.geometry.graph_steps import StepGraph, graphs_on
from kdsl.runtime.alloc import copy, empty, zeros
from kdsl.runtime.array import array
from kdsl.runtime.launch import Launch, launch
from kdsl.stdlib.hash_grid import hash_grid_cell, hash_grid_cell_coord
from kdsl.types import float32, int32, uint64, vec3
from kdsl.utils.merge_sort import MergeSortKeys
from kdsl.utils.sort import SortKeys

#: The index of the inverse cell width among each build's first kernel's parameters.
_INV = 2


@kernel
def _bucket_keys(
    points: array(dtype=vec3), n: int32, inv: float32, emptied: int32, dim_x: int32,
    dim_y: int32, dim_z: int32, keys: array(dtype=uint64), starts: array(dtype=int32),
    ends: array(dtype=int32),
):  # fmt: skip
    # Launched over max(n, emptied): keys[:emptied] hold the previous build's sorted
    # keys, whose buckets are emptied before this thread's key replaces its slot.
    i = tid()
    if i < emptied:
        old = int32(keys[i] >> uint64(32))
        starts[old] = 0
        ends[old] = 0
    if i < n:
        p = points[i]
        x = hash_grid_cell_coord(p[0] * inv)
        y = hash_grid_cell_coord(p[1] * inv)
        z = hash_grid_cell_coord(p[2] * inv)
        c = hash_grid_cell(x, y, z, dim_x, dim_y, dim_z)
        keys[i] = (uint64(c) << uint64(32)) | uint64(i)


@kernel
def _bucket_ranges(
    keys: array(dtype=uint64), n: int32, point_ids: array(dtype=int32),
    starts: array(dtype=int32), ends: array(dtype=int32),
):  # fmt: skip
    # Sorted keys: a bucket starts where its bucket differs from the previous key's and
    # ends where it differs from the next one's; each bucket's two entries are written once.
    i = tid()
    k = keys[i]
    c = int32(k >> uint64(32))
    point_ids[i] = int32(k & uint64(0xFFFFFFFF))
    if i == 0 or int32(keys[i - 1] >> uint64(32)) != c:
        starts[c] = i
    if i == n - 1 or int32(keys[i + 1] >> uint64(32)) != c:
        ends[c] = i + 1


@kernel
def _count_points(
    points: array(dtype=vec3), n: int32, inv: float32, dim_x: int32, dim_y: int32,
    dim_z: int32, buckets: array(dtype=int32), slots: array(dtype=int32),
    counts: array(dtype=int32),
):  # fmt: skip
    i = tid()
    p = points[i]
    x = hash_grid_cell_coord(p[0] * inv)
    y = hash_grid_cell_coord(p[1] * inv)
    z = hash_grid_cell_coord(p[2] * inv)
    c = hash_grid_cell(x, y, z, dim_x, dim_y, dim_z)
    buckets[i] = c
    slots[i] = atomic_add(counts, c, 1)


@kernel
def _count_scatter(
    buckets: array(dtype=int32), slots: array(dtype=int32), offsets: array(dtype=int32),
    n: int32, counts: array(dtype=int32), scattered: array(dtype=int32),
):  # fmt: skip
    # Slots fill a bucket's range from its end (no read of its count, which this kernel
    # zeroes for the next build). The test is a guard: counts are zero at a build's start
    # (``_Build.run`` zeroes them after a build cut short by an error).
    i = tid()
    c = buckets[i]
    at = offsets[c + 1] - 1 - slots[i]
    if at >= 0 and at < n:
        scattered[at] = i
    counts[c] = 0


@kernel
def _count_order(
    scattered: array(dtype=int32), buckets: array(dtype=int32), offsets: array(dtype=int32),
    n: int32, point_ids: array(dtype=int32),
):  # fmt: skip
    k = tid()
    v = scattered[k]
    c = buckets[v]
    start = offsets[c]
    rank = int32(0)
    for j in range(start, offsets[c + 1]):
        if scattered[j] < v:
            rank += 1
    if start + rank < n:  # as in _count_scatter
        point_ids[start + rank] = v


#: Counts each thread of the counting sort's scan adds up in turn (a level's chunk).
SCAN_CHUNK = 64


@kernel
def _chunk_sums(values: array(dtype=int32), m: int32, chunk: int32, sums: array(dtype=int32)):
    t = tid()
    total = int32(0)
    for j in range(t * chunk, vmin(t * chunk + chunk, m)):
        total += values[j]
    sums[t] = total


@kernel
def _top_prefix(values: array(dtype=int32), m: int32, prefix: array(dtype=int32)):
    # One thread: the exclusive prefix sums of the top level's few values.
    total = int32(0)
    for j in range(m):
        prefix[j] = total
        total += values[j]


@kernel
def _chunk_prefix(
    values: array(dtype=int32), m: int32, chunk: int32, base: array(dtype=int32),
    inclusive: int32, out: array(dtype=int32),
):  # fmt: skip
    # Each chunk's prefix sums from the sum of the chunks before it (``base``, the level
    # above's exclusive prefix): exclusive on the levels above, inclusive on the last.
    t = tid()
    run = base[t]
    for j in range(t * chunk, vmin(t * chunk + chunk, m)):
        v = values[j]
        if inclusive != 0:
            out[j] = run + v
        else:
            out[j] = run
        run += v


class _Scan:
    """The inclusive prefix sums of ``values`` into ``out`` (both int32, one size) as
    kdsl launches, prepared once: sums of chunks of ``SCAN_CHUNK`` level by level up to
    a few, one thread's prefix of those, then each level's chunks' prefixes back down
    (2M counts: three levels, seven launches). CuPy's scan of the same took 114 us of
    host time on an H200, a launch about 6."""

    def __init__(self, values: array, out: array) -> None:
        device, chunk = values.device, SCAN_CHUNK
        sizes = [values.shape[0]]
        while sizes[-1] > chunk or len(sizes) == 1:
            sizes.append(-(-sizes[-1] // chunk))
        # Each level above the first: its sums, then their exclusive prefix.
        block = empty(2 * sum(sizes[1:]), dtype=int32, device=device)
        sums, prefix, at = [values], [out], 0
        for m in sizes[1:]:
            sums.append(block[at : at + m])
            prefix.append(block[at + m : at + 2 * m])
            at += 2 * m

        def step(kernel_: Any, dim: int, inputs: list) -> Callable[[], None]:
            return launch(kernel_, dim=dim, device=device, inputs=inputs, record_cmd=True).launch

        top = len(sizes) - 1
        self.steps = [step(_chunk_sums, sizes[k + 1], [sums[k], sizes[k], chunk, sums[k + 1]])
                      for k in range(top)]  # fmt: skip
        self.steps.append(step(_top_prefix, 1, [sums[top], sizes[top], prefix[top]]))
        self.steps += [step(_chunk_prefix, sizes[k + 1],
                            [sums[k], sizes[k], chunk, prefix[k + 1], int(k == 0), prefix[k]])
                       for k in reversed(range(top))]  # fmt: skip

    def __call__(self) -> None:
        """Write the prefix sums."""
        for step in self.steps:
            step()


class _Steps:
    """One build's prepared steps for ``points`` (``n`` of them) after a build of
    ``emptied``: run again while those stay the same (it holds ``points``, as its
    prepared launches do, until the grid builds another array). ``graphed`` (a GPU's
    counting sort, all kernel launches on the first one's stream): from the second run
    at one cell width, one graph replay (``graph_steps.StepGraph``); a new cell width
    drops the graph (its first launch holds the old one)."""

    __slots__ = ("emptied", "first", "graph", "inv", "n", "points", "steps")

    def __init__(self, points: array, n: int, emptied: int, inv: np.float32,
                 first: Launch | None, steps: list[Callable[[], None]],
                 graphed: bool = False) -> None:  # fmt: skip
        self.points, self.n, self.emptied, self.inv = points, n, emptied, inv
        self.first, self.steps = first, steps
        self.graph = StepGraph(steps, first.stream if first is not None else None, graphed)

    def matches(self, points: array, n: int, emptied: int) -> bool:
        """Whether these steps fit a build of ``points`` after one of ``emptied``."""
        return points is self.points and n == self.n and emptied == self.emptied

    def run(self, inv: np.float32) -> None:
        """Run the steps with cell width ``1 / inv``."""
        if inv != self.inv and self.first is not None:
            self.first.set_param_at_index(_INV, inv)
            self.inv = inv
            self.graph.drop()
        self.graph()


class _Build(ABC):
    """What both builds share: the point order's buffer, its growth, the steps' reuse."""

    def __init__(self, device: Any, dims: tuple[int, int, int]) -> None:
        self.device, self.dims = device, dims
        self.num_cells = dims[0] * dims[1] * dims[2]
        self.capacity = -1
        self.built = 0
        #: The original index of each point, in bucket order (its first ``built``).
        self.point_ids = empty(0, dtype=int32, device=device)
        self.cell_starts: array
        self.cell_ends: array
        #: The last build's prepared steps (their ``points`` is that build's array).
        self.steps: _Steps | None = None

    def reserve(self, n: int) -> None:
        """Grow the point buffers to ``n`` points, keeping the built grid as it is."""
        if n <= self.capacity:
            return
        point_ids = empty(n, dtype=int32, device=self.device)
        if self.built:
            copy(point_ids, self.point_ids, count=self.built)
        self.point_ids, self.capacity = point_ids, n
        self._grow(n)
        self.steps = None

    @abstractmethod
    def _grow(self, n: int) -> None:
        """Grow the build's own point buffers to ``n`` points (``point_ids`` has grown)."""

    @abstractmethod
    def _prepare(self, points: array, n: int, inv: np.float32) -> _Steps:
        """The prepared steps of a build over ``points`` after one of ``built``."""

    def run(self, points: array, n: int, inv: np.float32) -> None:
        """Build over ``points`` (``n``, within ``capacity``) with cell width ``1 / inv``.

        A build cut short by an error leaves an empty grid (tables zeroed), so the next
        one starts from the state every build expects."""
        steps = self.steps
        if steps is None or not steps.matches(points, n, self.built):
            steps = self.steps = self._prepare(points, n, inv)
        try:
            steps.run(inv)
        except BaseException:
            self.built, self.steps = 0, None
            self._clear()
            raise
        self.built = n

    @abstractmethod
    def _clear(self) -> None:
        """Zero the tables (and whatever else a build expects zero at its start)."""

    def _launch(self, kernel_: Any, dim: int, inputs: list) -> Launch:
        return launch(kernel_, dim=dim, device=self.device, inputs=inputs, record_cmd=True)


class SortBuild(_Build):
    """The build by a sort of unique keys (see the module docstring)."""

    def __init__(self, device: Any, dims: tuple[int, int, int]) -> None:
        super().__init__(device, dims)
        self.cell_starts = zeros(self.num_cells, dtype=int32, device=device)
        self.cell_ends = zeros(self.num_cells, dtype=int32, device=device)
        #: Sorted by the kdsl merge sort (then, on a GPU, one graph from a rebuild on),
        #: with scratch keys after the keys, or by ``SortKeys``.
        self.kernel_sort = kernel_sort_on(device)
        self.keys = self._scratch = empty(0, dtype=uint64, device=device)

    def _clear(self) -> None:
        self.cell_starts.zero_()
        self.cell_ends.zero_()

    def _grow(self, n: int) -> None:
        block = empty(2 * n if self.kernel_sort else n, dtype=uint64, device=self.device)
        keys = block[:n]
        if self.built:  # the next build empties the buckets they name
            copy(keys, self.keys, count=self.built)
        self.keys, self._scratch = keys, block[n:]

    def _prepare(self, points: array, n: int, inv: np.float32) -> _Steps:
        tables = [self.cell_starts, self.cell_ends]
        emptied, keys = self.built, self.keys
        first = self._launch(_bucket_keys, max(n, emptied),
                             [points, n, inv, emptied, *self.dims, keys, *tables])  # fmt: skip
        steps: list[Callable[[], None]] = [first.launch]
        if n:
            ranges = self._launch(_bucket_ranges, n, [keys, n, self.point_ids, *tables])
            sort = (MergeSortKeys(keys[:n], self._scratch[:n]).steps if self.kernel_sort
                    else [SortKeys(keys[:n])])  # fmt: skip
            steps += [*sort, ranges.launch]
        graphed = self.kernel_sort and graphs_on(self.device)
        return _Steps(points, n, emptied, inv, first, steps, graphed)


class CountBuild(_Build):
    """The build by a counting sort (see the module docstring)."""

    def __init__(self, device: Any, dims: tuple[int, int, int]) -> None:
        super().__init__(device, dims)
        cells = self.num_cells
        self.counts = zeros(cells, dtype=int32, device=device)
        self.offsets = zeros(cells + 1, dtype=int32, device=device)
        self.cell_starts, self.cell_ends = self.offsets[:cells], self.offsets[1:]
        self._scan = _Scan(self.counts, self.cell_ends)
        self._scratch = empty(0, dtype=int32, device=device)

    def _clear(self) -> None:
        self.counts.zero_()
        self.offsets.zero_()

    def _grow(self, n: int) -> None:
        # Bucket, slot and scattered order of each point, in one allocation.
        self._scratch = empty(3 * n, dtype=int32, device=self.device)

    def _prepare(self, points: array, n: int, inv: np.float32) -> _Steps:
        m = self.capacity
        buckets, slots, scattered = (self._scratch[k * m : k * m + n] for k in range(3))
        scan = self._scan
        if not n:  # no points: the scan of zero counts empties every bucket
            return _Steps(points, n, self.built, inv, None, [scan])
        first = self._launch(_count_points, n,
                             [points, n, inv, *self.dims, buckets, slots, self.counts])  # fmt: skip
        scatter = self._launch(_count_scatter, n,
                               [buckets, slots, self.offsets, n, self.counts, scattered])  # fmt: skip
        order = self._launch(_count_order, n,
                             [scattered, buckets, self.offsets, n, self.point_ids])  # fmt: skip
        steps = [first.launch, scan, scatter.launch, order.launch]
        return _Steps(points, n, self.built, inv, first, steps, graphs_on(self.device))


def builder(device: Any, dims: tuple[int, int, int]) -> _Build:
    """The build a grid on ``device`` uses: the sort of keys (on a GPU with the kdsl
    merge sort), or the counting sort where ``counting_sort_on`` says so (measured:
    ``docs/performance.md``)."""
    return CountBuild(device, dims) if counting_sort_on(device) else SortBuild(device, dims)


def kernel_sort_on(device: Any) -> bool:
    """Whether the sort build on ``device`` sorts with the kdsl merge sort (a GPU's:
    no host synchronization, one graph) rather than ``SortKeys`` (NumPy's on the CPU)."""
    return bool(device.is_cuda)


def counting_sort_on(device: Any) -> bool:
    """Whether grids on ``device`` build by the counting sort (tests try both anywhere):
    nowhere by default. On an H200 its scan of every cell's count (2M for a 128^3 grid,
    seven launches) took more GPU time than the sort build's merge sort of 200k keys."""
    return False
