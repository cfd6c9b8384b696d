"""The ``"lbvh"`` BVH constructor: a linear BVH built on the boxes' device by kdsl kernels.

Karras' binary radix tree ("Maximizing parallelism in the construction of BVHs, octrees
and k-d trees", HPG 2012) over the items sorted by the Morton code of their centre (30
bits, 10 per axis, in the centres' bounding box), emitted bottom up as Apetrei does
("Fast and simple agglomerative LBVH construction", 2014). Each item's sort key is one
64-bit integer: its group id (with groups) above its Morton code above its own index,
so the keys are distinct (ties between equal codes break by item index), every group
is a contiguous run that becomes one subtree, and one plain sort of the keys sorts
the items (no key-value sort, no gathers). Inner node ``s`` of the radix tree splits
its sorted range ``[a, b]`` between ``s`` and ``s + 1``; sorted item ``k`` is leaf
``n - 1 + k``. Every node covers a contiguous range, which makes the rest parallel:

- a node with at most ``leaf_size`` items of one group becomes a leaf (its subtree is
  dropped): it is *kept* when its parent is not such a leaf;
- depth-first preorder sorts the kept nodes by ``(a, -b)``: nodes starting at a
  smaller position come first, and of the nodes starting at ``a`` (a chain of left
  children) the larger comes first. So a node's preorder number is the number of kept
  nodes starting before ``a`` (an inclusive scan of per-position counts) plus its rank
  in its chain (a short walk up its parents), and ``skip`` is the number of kept nodes
  starting before ``b + 1`` (``use_scan``, a CPU's way). Without the scan (a GPU's way:
  one host call less, longer walks being cheap there), the preorder number is a walk
  up to the root, each ancestor adding itself and, where the node lies in its right
  subtree, the kept size of its left one; ``skip`` is that number plus the node's kept
  size.

The build (``LbvhBuild``) is four kernels, one sort and (on a CPU) one scan, all on the
device, with no read back and no fill: the centres' bounds; the keys; the hierarchy (a
thread per leaf climbs, and at each parent the second child's thread to arrive, after
an arrival counter and fences as in the bottom-up refit of ``device_tree``, writes the
parent's range, bounds, kept size and kept-node counts, then climbs on); the preorder
kernel (writes every kept node at its preorder number, packed, with its bounds: no
refit).
The number of kept nodes stays on the device (``DeviceTree.node_count``): the tree's
arrays have ``2n - 1`` slots, those after the last node marked ``first = -2``
(``UNUSED``). Its buffers are views of one allocation (which the tree's
``rebuild`` keeps alive); the launches are prepared once
(``record_cmd``) and ``rebuild`` runs them again over the same buffers, which every
build leaves as it found them (the zeroed counters zero again). On a GPU a build sorts
with the kdsl merge sort (CuPy's synchronizes the stream), so the host never waits for
a build, and runs as one captured CUDA graph from its second run (``LbvhBuild.run``). A
fresh tree over the same boxes as a collected one takes its build (``recycle``,
``BUILDS``).
"""

from __future__ import annotations

import functools
import itertools
import weakref

from kdsl.errors import KdslError
from kdsl.frontend.api import atomic_add, atomic_max, cast, func, inf, kernel, thread_fence, tid
from kdsl.frontend.api import max as vmax
from kdsl.frontend.api import min as vmin
from kdsl.geometry.device_tree import UNUSED, DeviceTree, node_fields
from kdsl.geometry.graph_steps import StepGraph, graphs_on
from kdsl.geometry.recycle import RecycleBin
from kdsl.runtime.alloc import empty
from kdsl.runtime.array import array
from kdsl.runtime.carve import carve
from kdsl.runtime.launch import Launch, launch
from kdsl.runtime.stream import current_stream
from kdsl.stdlib.bvh import BvhNode, inner_first
from kdsl.types import float32, int32, uint64, vec2i, vec3
from kdsl.utils.merge_sort import MergeSortKeys
from kdsl.utils.scan import ScanInto
from kdsl.utils.sort import SortKeys

#: Boxes a thread reduces in the centres' bounds, per device kind: on a GPU few (many
#: threads, each reading with a stride of the thread count, so a warp's loads are
#: contiguous), on a CPU many (a contiguous chunk per thread, a few hundred threads).
_CHUNK = {"cuda": 64, "cpu": 1024}
#: The largest bit pattern of a float32 that is not NaN (+inf), as an int.
_INF_BITS = 0x7F800000
#: The int32 slots the centres' bounds are reduced into: four per axis (see ``_bound_key``).
BOUND_SLOTS = 12
#: Bits of a full Morton code (10 per axis).
MORTON_BITS = 30


@func
def _bound_max(slots: array(dtype=int32), s: int, x: float):
    """Fold the non-NaN float ``x`` into the maximum kept in zeroed int32 slots ``s`` and
    ``s + 1`` by ``atomic_max``: a float with its sign bit clear in slot ``s`` as its bits
    plus one, one with the sign bit set in slot ``s + 1`` as ``inf`` bits plus one less its
    magnitude bits (both orders agree with the floats'; zero means none)."""
    b = cast(x, int32)
    if b >= 0:
        atomic_max(slots, s, b + 1)
    else:
        atomic_max(slots, s + 1, _INF_BITS + 1 - (b & 0x7FFFFFFF))


@func
def _bound_value(slots: array(dtype=int32), s: int) -> float:
    """The maximum ``_bound_max`` kept in slots ``s`` and ``s + 1`` (0.0 when none)."""
    p = slots[s]
    if p > 0:
        return cast(p - 1, float32)
    q = slots[s + 1]
    if q > 0:
        return cast((_INF_BITS + 1 - q) | int32(-2147483648), float32)
    return 0.0


@kernel
def _centre_bounds_kernel(
    lowers: array(dtype=vec3), uppers: array(dtype=vec3), n: int32, chunk: int32,
    first_step: int32, step: int32, slots: array(dtype=int32),
):  # fmt: skip
    # Thread t reduces the centres of boxes t * first_step + k * step (k < chunk) and folds
    # its bounds into ``slots`` (zeros before): per axis a the maximum in slots 4a, 4a + 1
    # and the maximum of the negated centres (the minimum) in slots 4a + 2, 4a + 3. A NaN
    # coordinate is left out (the comparisons are false for it).
    t = tid()
    lo = vec3(inf, inf, inf)
    hi = vec3(-inf, -inf, -inf)
    for k in range(chunk):
        i = t * first_step + k * step
        if i < n:
            c = 0.5 * (lowers[i] + uppers[i])
            for a in range(3):
                if c[a] < lo[a]:
                    lo[a] = c[a]
                if c[a] > hi[a]:
                    hi[a] = c[a]
    for a in range(3):
        if lo[a] <= hi[a]:  # a non-NaN centre coordinate was seen
            _bound_max(slots, 4 * a, hi[a])
            _bound_max(slots, 4 * a + 2, -lo[a])


def centre_bounds(lowers: array, uppers: array, slots: array, backend: str | None = None,
                  strided: bool | None = None, record_cmd: bool = False) -> Launch | None:  # fmt: skip
    """Reduce the bounds of the boxes' centres into ``slots`` (``BOUND_SLOTS`` zeroed
    int32) in one launch of ``_CHUNK`` boxes a thread; ``_morton_keys`` decodes them.
    NaN centre coordinates are left out; an axis without any decodes as 0.0. A thread
    reads every ``threads``-th box when ``strided`` (coalesced: a GPU's default), else a
    contiguous chunk (a CPU's). ``record_cmd``: return the launch prepared, not run."""
    device = lowers.device
    n = lowers.shape[0]
    chunk = _CHUNK["cuda" if device.is_cuda else "cpu"]
    threads = -(-n // chunk)
    strided = device.is_cuda if strided is None else strided
    first_step, step = (1, threads) if strided else (chunk, 1)
    return launch(_centre_bounds_kernel, dim=threads, device=device, backend=backend,
                  inputs=[lowers, uppers, n, chunk, first_step, step, slots],
                  record_cmd=record_cmd)  # fmt: skip


@func
def _spread_bits(v: uint64) -> uint64:
    """The low 10 bits of ``v`` spread to every third bit."""
    x = v & uint64(0x3FF)
    x = (x | (x << uint64(16))) & uint64(0x030000FF)
    x = (x | (x << uint64(8))) & uint64(0x0300F00F)
    x = (x | (x << uint64(4))) & uint64(0x030C30C3)
    x = (x | (x << uint64(2))) & uint64(0x09249249)
    return x


@func
def _quantize(x: float, lo: float, scale: float) -> uint64:
    # NaN centres (NaN boxes) land in cell 0: the comparison below is false for NaN.
    q = (x - lo) * scale
    if q >= 0.0:
        return uint64(vmin(q, 1023.0))
    return uint64(0)


@kernel
def _morton_keys(
    lowers: array(dtype=vec3), uppers: array(dtype=vec3),
    bounds: array(dtype=int32), groups: array(dtype=int32), has_groups: int32,
    morton_drop: int32, index_bits: int32, group_shift: int32, keys: array(dtype=uint64),
):  # fmt: skip
    # Item i's key: its group above its Morton code (less its ``morton_drop`` low bits)
    # above its index (``index_bits``).
    i = tid()
    c = 0.5 * (lowers[i] + uppers[i])
    lo = vec3()
    hi = vec3()
    for a in range(3):
        hi[a] = _bound_value(bounds, 4 * a)
        lo[a] = -_bound_value(bounds, 4 * a + 2)
    extent = hi - lo
    code = uint64(0)
    for k in range(3):
        scale = 0.0
        if extent[k] > 0.0:
            scale = 1023.0 / extent[k]
        code = code | (_spread_bits(_quantize(c[k], lo[k], scale)) << uint64(2 - k))
    key = ((code >> uint64(morton_drop)) << uint64(index_bits)) | uint64(i)
    if has_groups != 0:
        key = key | (uint64(groups[i]) << uint64(group_shift))
    keys[i] = key


@func
def _clz64(x: uint64) -> int:
    """Leading zero bits of ``x`` (64 for zero)."""
    if x == uint64(0):
        return 64
    v = x
    n = 0
    if (v >> uint64(32)) == uint64(0):
        n += 32
        v = v << uint64(32)
    if (v >> uint64(48)) == uint64(0):
        n += 16
        v = v << uint64(16)
    if (v >> uint64(56)) == uint64(0):
        n += 8
        v = v << uint64(8)
    if (v >> uint64(60)) == uint64(0):
        n += 4
        v = v << uint64(4)
    if (v >> uint64(62)) == uint64(0):
        n += 2
        v = v << uint64(2)
    if (v >> uint64(63)) == uint64(0):
        n += 1
    return n


@func
def _delta(keys: array(dtype=uint64), i: int, j: int) -> int:
    """Length of the common prefix of the (distinct) sorted keys ``i`` and ``j``."""
    return _clz64(keys[i] ^ keys[j])


@func
def _is_leaf(
    keys: array(dtype=uint64), a: int, b: int, leaf_size: int, group_shift: int
) -> bool:  # fmt: skip
    """Whether a node over sorted items ``[a, b]`` is a leaf: few items, one group (the
    key bits from ``group_shift`` up; 63 without groups, where that bit is zero)."""
    s = uint64(group_shift)
    return b - a + 1 <= leaf_size and (keys[a] >> s) == (keys[b] >> s)


@func
def _range_a(n: int, node_a: array(dtype=int32), x: int) -> int:
    """The first sorted item under radix-tree node ``x`` (a leaf from ``n - 1``)."""
    if x >= n - 1:
        return x - (n - 1)
    return node_a[x]


@func
def _range_b(n: int, node_b: array(dtype=int32), x: int) -> int:
    """The last sorted item under radix-tree node ``x``."""
    if x >= n - 1:
        return x - (n - 1)
    return node_b[x]


@kernel
def _emit_hierarchy(
    keys: array(dtype=uint64), n: int32, leaf_size: int32, group_shift: int32,
    index_mask: uint64, item_lowers: array(dtype=vec3), item_uppers: array(dtype=vec3),
    items: array(dtype=int32), parent: array(dtype=int32), left: array(dtype=int32),
    right: array(dtype=int32), node_lo: array(dtype=vec3), node_hi: array(dtype=vec3),
    node_a: array(dtype=int32), node_b: array(dtype=int32), sizes: array(dtype=int32),
    heights: array(dtype=int32), height: array(dtype=int32),
    arrivals: array(dtype=int32), use_scan: int32, starts: array(dtype=int32),
    before: array(dtype=int32), group_roots: array(dtype=int32),
):  # fmt: skip
    # Thread k: sorted item k (its index into ``items``, its box), then up the tree (see
    # the module docstring). Inner node s's parent is s (this node is its left child) or
    # a - 1 (its right child): the side whose neighbouring key shares the longer prefix.
    # Each inner node gets its range, bounds, kept size (its subtree's kept nodes) and
    # kept height (the most levels below it: 0 for a leaf); the root's kept size, the
    # tree's node count, goes to ``before[n]``, its height to ``height[0]``. With
    # ``use_scan``, the kept nodes are also counted by their first position a into
    # ``starts[a + 1]``. Every group's root is set to -1 (``_preorder`` writes them).
    k = tid()
    if k < group_roots.shape[0]:  # (more groups than threads: each sets several)
        for g in range(k, group_roots.shape[0], n):
            group_roots[g] = -1
    item = int(keys[k] & index_mask)
    items[k] = item
    lo = item_lowers[item]
    hi = item_uppers[item]
    node = n - 1 + k
    a = k
    b = k
    size = 1  # kept nodes in the subtree of ``node`` (a leaf's dropped subtree: 1)
    h = 0  # the kept height of ``node``'s subtree
    while True:
        if node < n - 1:  # an inner node, complete: publish it
            leaf = _is_leaf(keys, a, b, leaf_size, group_shift)
            if leaf:
                size = 1
                h = 0
            node_lo[node] = lo
            node_hi[node] = hi
            node_a[node] = a
            node_b[node] = b
            sizes[node] = size
            heights[node] = h
            if use_scan != 0 and not leaf:  # its children are kept
                atomic_add(starts, a + 1, 1)
                atomic_add(starts, node + 2, 1)
        if a == 0 and b == n - 1:  # the root, always kept
            parent[node] = -1
            before[n] = size
            height[0] = h
            if use_scan != 0:
                atomic_add(starts, 1, 1)
            return
        p = a - 1
        if a == 0 or (b != n - 1 and _delta(keys, b, b + 1) > _delta(keys, a - 1, a)):
            p = b
            left[p] = node
        else:
            right[p] = node
        parent[node] = p
        thread_fence()  # publish this node before its arrival
        if atomic_add(arrivals, p, 1) == 0:
            return  # the sibling's thread, arriving second, completes ``p``
        thread_fence()  # see the sibling, published before its arrival
        arrivals[p] = 0  # ready for the next build
        s = left[p]
        if s == node:
            s = right[p]
        if s >= n - 1:
            j = items[s - (n - 1)]
            lo = vmin(lo, item_lowers[j])
            hi = vmax(hi, item_uppers[j])
        else:
            lo = vmin(lo, node_lo[s])
            hi = vmax(hi, node_hi[s])
        a = vmin(a, _range_a(n, node_a, s))
        b = vmax(b, _range_b(n, node_b, s))
        size = size + _kept_size(n, sizes, s) + 1
        if s < n - 1:
            h = vmax(h, heights[s])
        h = h + 1
        node = p


@func
def _kept_size(n: int, sizes: array(dtype=int32), x: int) -> int:
    """Kept nodes in the subtree of radix-tree node ``x`` (1 for a leaf)."""
    if x >= n - 1:
        return 1
    return sizes[x]


@func
def _walk_preorder(
    n: int, parent: array(dtype=int32), left: array(dtype=int32), sizes: array(dtype=int32),
    x: int,
) -> vec2i:  # fmt: skip
    """(the preorder number of kept node ``x``, its parent's, -1 for the root), from a
    walk up to the root: each ancestor adds itself, and the kept nodes of its left
    subtree where ``x`` is in its right one."""
    pre = 0
    first_step = 0
    c = x
    p = parent[x]
    while p >= 0:
        step = 1
        if left[p] != c:
            step = step + _kept_size(n, sizes, left[p])
        if c == x:
            first_step = step
        pre = pre + step
        c = p
        p = parent[p]
    up = -1
    if parent[x] >= 0:
        up = pre - first_step
    return vec2i(pre, up)


@func
def _chain_rank(
    n: int, node_a: array(dtype=int32), parent: array(dtype=int32), x: int
) -> int:  # fmt: skip
    """Kept ancestors of ``x`` starting at its position too (the chain of left children
    above it): ``x``'s preorder number is ``before[a]`` plus this."""
    a = _range_a(n, node_a, x)
    rank = 0
    p = parent[x]
    while p >= 0 and node_a[p] == a:
        rank += 1
        p = parent[p]
    return rank


@kernel
def _preorder(
    keys: array(dtype=uint64), n: int32, leaf_size: int32, group_shift: int32,
    has_groups: int32, items: array(dtype=int32), item_lowers: array(dtype=vec3),
    item_uppers: array(dtype=vec3), parent: array(dtype=int32), node_lo: array(dtype=vec3),
    node_hi: array(dtype=vec3), node_a: array(dtype=int32), node_b: array(dtype=int32),
    left: array(dtype=int32), sizes: array(dtype=int32), use_scan: int32,
    before: array(dtype=int32), skip: array(dtype=int32), first: array(dtype=int32),
    count: array(dtype=int32), lowers: array(dtype=vec3), uppers: array(dtype=vec3),
    packed_first: array(dtype=int32), packed_next: array(dtype=int32),
    with_parents: int32, pre_parent: array(dtype=int32), group_roots: array(dtype=int32),
    starts: array(dtype=int32), bounds: array(dtype=int32),
):  # fmt: skip
    # Thread x: radix-tree node x, written at its preorder number when kept (links,
    # contiguous ``first``/``count`` for the refit, packed node (an inner one naming its
    # right child, ``inner_first``) and bounds, and, with
    # ``with_parents``, its parent's preorder number: a kept node's parent is kept); and
    # slot x, when past the last node, marked unused. The preorder number comes from the
    # scan of the kept nodes' first positions (``before``) and a short walk up the chain
    # of left children (``use_scan``: fewer steps, for a CPU), or from a walk up to the
    # root over the kept sizes (no scan: one step less to issue, for a GPU). Zeroes
    # ``starts`` and ``bounds`` for the next build (nothing reads them after the scan).
    x = tid()
    slots = 2 * n - 1
    if x <= n:  # (n == 1: one thread, two counts)
        for z in range(x, n + 1, slots):
            starts[z] = 0
    if x < bounds.shape[0]:
        for z in range(x, bounds.shape[0], slots):
            bounds[z] = 0
    if x >= before[n]:
        skip[x] = x + 1
        first[x] = UNUSED
        count[x] = 0
        packed_first[x] = UNUSED
        packed_next[x] = 0
        lowers[x] = vec3()
        uppers[x] = vec3()
        if with_parents != 0:
            pre_parent[x] = -1
    q = parent[x]
    if q >= 0 and _is_leaf(keys, node_a[q], node_b[q], leaf_size, group_shift):
        return  # inside a leaf: not kept
    a = _range_a(n, node_a, x)
    b = _range_b(n, node_b, x)
    pre = 0
    after = 0
    up = -1  # the parent's preorder number
    if use_scan != 0:
        pre = before[a] + _chain_rank(n, node_a, parent, x)
        after = before[b + 1]
        if q >= 0:
            up = pre - 1  # the left child follows its parent
            if node_a[q] != a:
                up = before[node_a[q]] + _chain_rank(n, node_a, parent, q)
    else:
        walk = _walk_preorder(n, parent, left, sizes, x)
        pre = walk[0]
        up = walk[1]
        after = pre + _kept_size(n, sizes, x)
    skip[pre] = after
    if x >= n - 1:
        j = items[a]
        lowers[pre] = item_lowers[j]
        uppers[pre] = item_uppers[j]
    else:
        lowers[pre] = node_lo[x]
        uppers[pre] = node_hi[x]
    if _is_leaf(keys, a, b, leaf_size, group_shift):
        first[pre] = a
        packed_first[pre] = a
        packed_next[pre] = b - a + 1
        count[pre] = b - a + 1
    else:
        first[pre] = -1
        # the right child: after the parent and the left child's kept subtree
        packed_first[pre] = inner_first(pre + 1 + _kept_size(n, sizes, left[x]))
        packed_next[pre] = after
        count[pre] = 0
    if with_parents != 0:
        pre_parent[pre] = up
    if has_groups != 0:  # the root of a group: one group, its parent (if any) spans two
        s = uint64(group_shift)
        g = keys[a] >> s
        top = q < 0 or (keys[node_a[q]] >> s) != (keys[node_b[q]] >> s)
        if g == (keys[b] >> s) and top:
            group_roots[int(g)] = pre


def key_layout(n: int, num_groups: int) -> tuple[int, int, int]:
    """``(morton_drop, index_bits, group_shift)``: the Morton bits dropped so the group
    id (with groups), the Morton code and an item index fit in 63 bits of a key, the
    index's bits, and where the group id starts (63 without groups: above every key).
    Raises ``KdslError`` when the groups leave no room for a Morton code."""
    index_bits = max(1, (n - 1).bit_length())
    group_bits = max(num_groups - 1, 0).bit_length() if num_groups else 0
    morton = min(MORTON_BITS, (63 - index_bits - group_bits) // 3 * 3)
    if morton < 3:
        raise KdslError(f"{num_groups} groups of {n} boxes leave no key bits for the lbvh "
                         "build's Morton codes")  # fmt: skip
    shift = index_bits + morton if num_groups else 63
    return MORTON_BITS - morton, index_bits, shift


def device_sort_on(device) -> bool:
    """Whether lbvh builds on ``device`` sort their keys with the kdsl merge sort
    (``kdsl.utils.merge_sort``: kernel launches only, so nothing waits for the device
    and the build can be one graph) rather than with ``SortKeys`` (CuPy's sort on a
    GPU, NumPy's on the CPU, which stays faster there). Tests try both anywhere."""
    return bool(device.is_cuda)


class LbvhBuild:
    """One lbvh build's buffers and prepared steps over boxes ``lowers``/``uppers`` (and
    ``groups``): ``tree`` is the ``DeviceTree`` it writes; each call of ``run`` builds
    it again from the boxes' current values (same count), allocating nothing."""

    def __init__(self, lowers: array, uppers: array, leaf_size: int, groups: array | None,
                 num_groups: int, bottom_up: bool, use_scan: bool) -> None:  # fmt: skip
        device = lowers.device
        n = lowers.shape[0]
        slots = 2 * n - 1
        roots = max(num_groups, 1)
        morton_drop, index_bits, group_shift = key_layout(n, num_groups)
        has_groups = int(groups is not None)
        # One block of packed nodes (one allocation, one fill): the tree's nodes,
        # then, as views of the rest, the radix tree's inner nodes' bounds, the keys and
        # the int32 arrays. Every element of ``ints`` is written before it is read;
        # ``zero`` must start at zero, and every build leaves it so (``arrivals``, the
        # refit's counters, which refits leave even: see ``device_tree``).
        layout = {"items": n, "skip": slots, "first": slots, "count": slots, "parent": slots,
                  "left": n - 1, "right": n - 1, "node_a": n - 1, "node_b": n - 1,
                  "kept": n - 1, "heights": n - 1, "height": 1, "before": n + 1,
                  "pre_parent": slots if bottom_up else 0, "group_roots": roots}  # fmt: skip
        zero_sizes = {"starts": n + 1, "climbs": n - 1, "arrivals": slots if bottom_up else 0,
                      "bounds": BOUND_SLOTS}  # fmt: skip
        num_ints = sum(layout.values()) + sum(zero_sizes.values())
        # With the kdsl sort (a GPU's), its scratch keys follow the keys.
        sorted_by_kernels = device_sort_on(device)
        num_keys = 2 * n if sorted_by_kernels else n
        tail = 24 * (n - 1) + 8 * num_keys + 4 * num_ints  # inner bounds, keys, ints
        # (an uninitialized struct allocation, then one fill of the int32 arrays that
        # must start at zero: a zero-filled struct array is slow to make on the CPU)
        self._block = empty(slots + -(-tail // 32), dtype=BvhNode, device=device)
        at_keys = 32 * slots + 24 * (n - 1)
        at_ints = at_keys + 8 * num_keys
        sizes = {**layout, **zero_sizes}
        offsets = [at_ints + 4 * k for k in itertools.accumulate([0, *sizes.values()])]
        # Every view in one call (``carve``): the nodes and their fields' strided views,
        # the inner nodes' bounds, the keys and their scratch, the int32 arrays, and
        # the zeroed ones as one array (for the fill).
        made = carve(self._block, [
            (0, BvhNode, slots), *node_fields(slots),
            (32 * slots, vec3, n - 1), (32 * slots + 12 * (n - 1), vec3, n - 1),
            (at_keys, uint64, n), (at_keys + 8 * n, uint64, num_keys - n),
            (offsets[len(layout)], int32, sum(zero_sizes.values())),
            *((at, int32, size) for at, size in zip(offsets, sizes.values())),
        ])  # fmt: skip
        nodes, lo, packed_first, hi, packed_next = made[:5]
        node_lo, node_hi, keys, scratch, zero_block = made[5:10]
        ints = dict(zip(sizes, made[10:]))
        views = (lo, packed_first, hi, packed_next)
        zero = {name: ints[name] for name in zero_sizes}
        zero_block.zero_()  # ``zero``: the last arrays of the block
        node_a, node_b = ints["node_a"], ints["node_b"]
        group_arg = groups if groups is not None else zero["bounds"]
        with_parents = int(bottom_up)

        def prepared(kernel, dim: int, inputs: list) -> Launch:
            return launch(kernel, dim=dim, device=device, inputs=inputs, record_cmd=True)

        bounds = centre_bounds(lowers, uppers, zero["bounds"], record_cmd=True)
        self._before = [
            bounds.launch,
            prepared(_morton_keys, n, [lowers, uppers, zero["bounds"], group_arg, has_groups,
                                       morton_drop, index_bits, group_shift, keys]).launch,
        ]  # fmt: skip
        self._after = [
            prepared(_emit_hierarchy, n, [
                keys, n, leaf_size, group_shift, (1 << index_bits) - 1, lowers, uppers,
                ints["items"], ints["parent"], ints["left"], ints["right"], node_lo, node_hi,
                node_a, node_b, ints["kept"], ints["heights"], ints["height"], zero["climbs"],
                int(use_scan), zero["starts"], ints["before"], ints["group_roots"]]).launch,
            *([ScanInto(zero["starts"], ints["before"])] if use_scan else []),
            prepared(_preorder, slots, [
                keys, n, leaf_size, group_shift, has_groups, ints["items"], lowers, uppers,
                ints["parent"], node_lo, node_hi, node_a, node_b, ints["left"], ints["kept"],
                int(use_scan), ints["before"], ints["skip"], ints["first"], ints["count"], lo,
                hi, packed_first, packed_next, with_parents, ints["pre_parent"],
                ints["group_roots"], zero["starts"], zero["bounds"]]).launch,
        ]  # fmt: skip
        # With the kdsl sort, every step is a launch: without the scan, one graph from
        # the second run.
        if sorted_by_kernels:
            sort = MergeSortKeys(keys, scratch).steps
            graphed = not use_scan and graphs_on(device)
        else:
            sort, graphed = [SortKeys(keys)], False
        self._steps = StepGraph([*self._before, *sort, *self._after], bounds.stream, graphed)
        self.runs = 0
        self._tree_fields = (
            ints["skip"], ints["first"], ints["count"], ints["items"],
            ints["group_roots"][:num_groups], ints["pre_parent"], zero["arrivals"], slots,
            nodes, views, ints["before"][n:], ints["height"],
        )  # fmt: skip
        #: Whether the last run completed (a run cut short may leave counters nonzero).
        self.clean = True

    def run(self) -> None:
        """Build the tree (again) from the boxes' current values.

        With the kdsl sort (``device_sort_on``; its merges are two prepared launches
        whatever the count, so a build made once prepares five), a GPU build runs its
        steps one by one the first time and as one captured graph from then on
        (``graph_steps``). Both sorts order the distinct keys alike: the same tree."""
        self.clean = False
        self._steps()
        self.runs += 1
        self.clean = True

    def new_tree(self) -> DeviceTree:
        """A ``DeviceTree`` over this build's arrays (one per owner: see ``build_lbvh``)."""
        *links, slots, nodes, views, node_count, height = self._tree_fields
        return DeviceTree(*links, slots, nodes, views, node_count=node_count, bounded=True,
                          height=height)  # fmt: skip


#: The builds of collected trees, for the next tree over the same boxes (``recycle``):
#: two, a BVH's and a mesh's, say.
BUILDS = RecycleBin(2)


def _rebuild(build: LbvhBuild, tree: weakref.ref) -> None:
    build.run()
    t = tree()
    if t is not None:
        t.forget_count()


def build_lbvh(lowers: array, uppers: array, leaf_size: int, groups: array | None,
               num_groups: int, bottom_up: bool | None = None,
               use_scan: bool | None = None) -> DeviceTree:  # fmt: skip
    """Build a ``DeviceTree`` over the boxes on their device (see the module docstring):
    its packed nodes written whole (links and bounds) and, for the bottom-up refit (on
    a GPU by default, anywhere with ``bottom_up=True``), its parents and arrival
    counters. ``use_scan`` numbers the nodes through a scan (a CPU's default) rather
    than walks up the tree (a GPU's: no scan to issue). ``tree.rebuild()`` builds it
    again over the same buffers."""
    device = lowers.device
    n = lowers.shape[0]
    leaf_size = max(1, int(leaf_size))
    if bottom_up is None:  # a GPU refits bottom up (``device_tree``), from parents
        bottom_up = device.is_cuda
    if use_scan is None:
        use_scan = not device.is_cuda
    if n == 0:
        none = empty(max(num_groups, 1), dtype=int32, device=device)
        none.fill_(-1)
        return DeviceTree(none[:0], none[:0], none[:0], none[:0], none[:num_groups], none[:0],
                          none[:0], 0)  # fmt: skip
    # Filed by what the prepared launches hold: the arrays and the stream they run on.
    inputs = (lowers, uppers, groups, None if device.is_cpu else current_stream(device))
    shape = (n, leaf_size, num_groups, bottom_up, use_scan)
    build = BUILDS.take(inputs, shape)
    if build is None:
        build = LbvhBuild(lowers, uppers, leaf_size, groups, num_groups, bottom_up, use_scan)
    build.run()
    tree = build.new_tree()
    tree.rebuild = functools.partial(_rebuild, build, weakref.ref(tree))
    BUILDS.keep_when_collected(tree, inputs, shape, build, lambda b: b.clean)
    return tree
