"""The ``"lbvh"`` BVH constructor: a linear BVH built on the boxes' device by kdsl kernels.

Karras' construction ("Maximizing parallelism in the construction of BVHs, octrees and
k-d trees", HPG 2012): the items are sorted by the Morton code of their centre (30
bits, 10 per axis, in the centres' bounding box; with groups, the group id above
them, so every group is a contiguous run and becomes one subtree); each of the
``n - 1`` inner nodes then finds its own range of sorted items and split independently
(equal codes are told apart by their positions). Every node covers a contiguous range
``[a, b]`` of the sorted items, which is what makes the rest parallel too:

- a node with at most ``leaf_size`` items of one group becomes a leaf (its subtree is
  dropped): it is *kept* when its parent is not such a leaf;
- depth-first preorder sorts the kept nodes by ``(a, -b)``: nodes starting at a
  smaller position come first, and of the nodes starting at ``a`` (a chain of left
  children) the larger comes first. So a node's preorder number is the number of kept
  nodes starting before ``a`` (an exclusive scan of per-position counts) plus its rank
  in its chain (a short walk up its parents), and ``skip`` is the number of kept nodes
  starting before ``b + 1``.

The leaves' items are the sorted item indices themselves. The build reads back from
the device one scalar, the number of kept nodes.
"""

from __future__ import annotations

from kdsl.frontend.api import atomic_add, atomic_max, cast, func, inf, kernel, tid
from kdsl.frontend.api import max as vmax
from kdsl.frontend.api import min as vmin
from kdsl.geometry.device_tree import DeviceTree, node_field
from kdsl.runtime.alloc import empty, zeros
from kdsl.runtime.array import array
from kdsl.runtime.launch import launch
from kdsl.stdlib.bvh import BvhNode
from kdsl.types import float32, int32, uint64, vec3
from kdsl.utils import array_scan, radix_sort_pairs

#: Boxes a thread reduces in the centres' bounds, per device kind: on a GPU few (many
#: threads, each reading with a stride of the thread count, so a warp's loads are
#: contiguous), on a CPU many (a contiguous chunk per thread, a few hundred threads).
_CHUNK = {"cuda": 64, "cpu": 1024}
#: The largest bit pattern of a float32 that is not NaN (+inf), as an int.
_INF_BITS = 0x7F800000
#: The int32 slots the centres' bounds are reduced into: four per axis (see ``_bound_key``).
BOUND_SLOTS = 12


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
                  strided: bool | None = None) -> None:  # fmt: skip
    """Reduce the bounds of the boxes' centres into ``slots`` (``BOUND_SLOTS`` zeroed
    int32) in one launch of ``_CHUNK`` boxes a thread; ``_morton_keys`` decodes them.
    NaN centre coordinates are left out; an axis without any decodes as 0.0. A thread
    reads every ``threads``-th box when ``strided`` (coalesced: a GPU's default), else a
    contiguous chunk (a CPU's)."""
    device = lowers.device
    n = lowers.shape[0]
    chunk = _CHUNK["cuda" if device.is_cuda else "cpu"]
    threads = -(-n // chunk)
    strided = device.is_cuda if strided is None else strided
    first_step, step = (1, threads) if strided else (chunk, 1)
    launch(_centre_bounds_kernel, dim=threads, device=device, backend=backend,
           inputs=[lowers, uppers, n, chunk, first_step, step, slots])  # fmt: skip


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
    keys: array(dtype=uint64), values: array(dtype=int32),
):  # fmt: skip
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
    if has_groups != 0:
        code = code | (uint64(groups[i]) << uint64(32))
    keys[i] = code
    values[i] = i


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
def _delta(keys: array(dtype=uint64), n: int, i: int, j: int) -> int:
    """Length of the common prefix of sorted keys ``i`` and ``j`` (their positions break
    ties), or -1 when ``j`` is out of range."""
    if j < 0 or j >= n:
        return -1
    a = keys[i]
    b = keys[j]
    if a == b:
        return 64 + _clz64(uint64(i ^ j))
    return _clz64(a ^ b)


@func
def _is_leaf(
    keys: array(dtype=uint64), a: int, b: int, leaf_size: int
) -> bool:  # fmt: skip
    """Whether a node over sorted items ``[a, b]`` is a leaf: few items, one group."""
    return b - a + 1 <= leaf_size and (keys[a] >> uint64(32)) == (keys[b] >> uint64(32))


@kernel
def _karras_nodes(
    keys: array(dtype=uint64), n: int32, leaf_size: int32, range_a: array(dtype=int32),
    range_b: array(dtype=int32), parent: array(dtype=int32), starts: array(dtype=int32),
    group_roots: array(dtype=int32),
):  # fmt: skip
    # Also counts the kept nodes by their first position ``a`` into ``starts[a + 1]``
    # (zeros before): the root, and both children of every inner node that is no leaf;
    # and sets every group's root to -1 (``_preorder`` writes the roots found).
    i = tid()
    for g in range(i, group_roots.shape[0], 2 * n - 1):
        group_roots[g] = -1
    if i >= n - 1:  # a leaf: node n - 1 + k holds sorted item k
        k = i - (n - 1)
        range_a[i] = k
        range_b[i] = k
        if n == 1:
            parent[i] = -1
            atomic_add(starts, 1, 1)
        return
    if i == 0:
        parent[0] = -1
        atomic_add(starts, 1, 1)
    d = 1
    if _delta(keys, n, i, i + 1) < _delta(keys, n, i, i - 1):
        d = -1
    dmin = _delta(keys, n, i, i - d)
    lmax = 2
    while _delta(keys, n, i, i + lmax * d) > dmin:
        lmax = lmax * 2
    ln = 0
    t = lmax // 2
    while t >= 1:
        if _delta(keys, n, i, i + (ln + t) * d) > dmin:
            ln = ln + t
        t = t // 2
    j = i + ln * d
    dnode = _delta(keys, n, i, j)
    s = 0
    div = 2
    t = (ln + div - 1) // div
    while t >= 1:
        if _delta(keys, n, i, i + (s + t) * d) > dnode:
            s = s + t
        if t == 1:
            break
        div = div * 2
        t = (ln + div - 1) // div
    gamma = i + s * d + vmin(d, 0)
    a = vmin(i, j)
    b = vmax(i, j)
    range_a[i] = a
    range_b[i] = b
    left = gamma
    if a == gamma:
        left = n - 1 + gamma
    right = gamma + 1
    if b == gamma + 1:
        right = n - 1 + gamma + 1
    parent[left] = i
    parent[right] = i
    if not _is_leaf(keys, a, b, leaf_size):  # its children are kept
        atomic_add(starts, a + 1, 1)
        atomic_add(starts, gamma + 2, 1)


@func
def _is_kept(
    keys: array(dtype=uint64), range_a: array(dtype=int32),
    range_b: array(dtype=int32), parent: array(dtype=int32), x: int,
    leaf_size: int,
) -> bool:  # fmt: skip
    p = parent[x]
    if p < 0:
        return True
    return not _is_leaf(keys, range_a[p], range_b[p], leaf_size)


@func
def _chain_rank(range_a: array(dtype=int32), parent: array(dtype=int32), x: int) -> int:
    """Kept ancestors of ``x`` starting at its position too (the chain of left children
    above it): ``x``'s preorder number is ``before[range_a[x]]`` plus this."""
    a = range_a[x]
    rank = 0
    p = parent[x]
    while p >= 0 and range_a[p] == a:
        rank += 1
        p = parent[p]
    return rank


@kernel
def _preorder(
    keys: array(dtype=uint64), range_a: array(dtype=int32),
    range_b: array(dtype=int32), parent: array(dtype=int32),
    leaf_size: int32, before: array(dtype=int32), has_groups: int32,
    skip: array(dtype=int32), first: array(dtype=int32), count: array(dtype=int32),
    group_roots: array(dtype=int32), node_first: array(dtype=int32),
    node_next: array(dtype=int32), with_parents: int32, pre_parent: array(dtype=int32),
):  # fmt: skip
    # Writes the kept node ``x`` at its preorder number: ``skip``, ``first``, ``count``
    # (contiguous, for the refit), the packed node's links (``BvhNode.first``, ``.next``) and, ``with_parents``, its parent's
    # preorder number (its Karras parent is kept too: a leaf's subtree is dropped whole).
    x = tid()
    if not _is_kept(keys, range_a, range_b, parent, x, leaf_size):
        return
    a = range_a[x]
    b = range_b[x]
    pre = before[a] + _chain_rank(range_a, parent, x)
    after = before[b + 1]
    skip[pre] = after
    if _is_leaf(keys, a, b, leaf_size):
        first[pre] = a
        node_first[pre] = a
        node_next[pre] = b - a + 1
        count[pre] = b - a + 1
    else:
        first[pre] = -1
        node_first[pre] = -1
        node_next[pre] = after
        count[pre] = 0
    q = parent[x]
    if with_parents != 0:
        up = -1
        if q >= 0:
            up = pre - 1  # the left child follows its parent
            if range_a[q] != a:
                up = before[range_a[q]] + _chain_rank(range_a, parent, q)
        pre_parent[pre] = up
    if has_groups != 0:  # the root of a group: one group, its parent (if any) spans two
        g = keys[a] >> uint64(32)
        top = q < 0 or (keys[range_a[q]] >> uint64(32)) != (keys[range_b[q]] >> uint64(32))
        if g == (keys[b] >> uint64(32)) and top:
            group_roots[int(g)] = pre


def build_lbvh(lowers: array, uppers: array, leaf_size: int, groups: array | None,
               num_groups: int, bottom_up: bool | None = None) -> DeviceTree:  # fmt: skip
    """Build a ``DeviceTree`` over the boxes on their device (see the module docstring),
    its packed nodes' links written (``DeviceTree.nodes``) and, for the bottom-up refit
    (on a GPU by default, anywhere with ``bottom_up=True``), its parents and arrival
    counters.

    Four allocations (each costs the host tens of microseconds on a GPU): the int32
    arrays are views of one block, those that start at zero (the counts of kept nodes,
    the arrival counters, the centres' bounds) of one zeroed block; the sort keys and the
    packed nodes have their own."""
    device = lowers.device
    n = lowers.shape[0]
    leaf_size = max(1, int(leaf_size))
    if bottom_up is None:  # a GPU refits bottom up (``device_tree``), from parents
        bottom_up = device.is_cuda
    nodes = 2 * n - 1
    roots = max(num_groups, 1)
    if n == 0:
        none = empty(roots, dtype=int32, device=device)
        none.fill_(-1)
        return DeviceTree(none[:0], none[:0], none[:0], none[:0], none[:num_groups], none[:0],
                          none[:0], 0)  # fmt: skip
    # Every element of ``block`` is written before it is read; ``zero`` starts at zero.
    sizes = {"values": 2 * n, "range_a": nodes, "range_b": nodes, "parent": nodes,
             "before": n + 1, "skip": nodes, "first": nodes, "count": nodes,
             "pre_parent": nodes if bottom_up else 0, "group_roots": roots}  # fmt: skip
    ints = _carve(empty(sum(sizes.values()), dtype=int32, device=device), sizes)
    zero_sizes = {"counts": n + 1, "arrivals": nodes if bottom_up else 0, "bounds": BOUND_SLOTS}
    zero = _carve(zeros(sum(zero_sizes.values()), dtype=int32, device=device), zero_sizes)
    centre_bounds(lowers, uppers, zero["bounds"])
    keys = empty(2 * n, dtype=uint64, device=device)
    values = ints["values"]
    group_arg = groups if groups is not None else zero["bounds"]
    launch(
        _morton_keys, dim=n, device=device,
        inputs=[lowers, uppers, zero["bounds"], group_arg, int(groups is not None), keys, values],
    )  # fmt: skip
    # Only the Morton code's 30 bits and the group id's bits above bit 32 decide the order.
    key_bits = 32 + max(num_groups - 1, 0).bit_length() if groups is not None else 30
    radix_sort_pairs(keys, values, n, end_bit=key_bits)
    range_a, range_b, parent = ints["range_a"], ints["range_b"], ints["parent"]
    counts = zero["counts"]  # kept nodes starting at a, at a + 1
    group_roots = ints["group_roots"]
    launch(_karras_nodes, dim=nodes, device=device,
           inputs=[keys, n, leaf_size, range_a, range_b, parent, counts, group_roots])  # fmt: skip
    before = ints["before"]  # kept nodes starting before each position
    array_scan(counts, before, inclusive=True)
    # The packed nodes, allocated for the most nodes (the count comes back below).
    packed = empty(nodes, dtype=BvhNode, device=device)
    node_first, node_next = node_field(packed, 12, int32), node_field(packed, 28, int32)
    skip, first, count, pre_parent = ints["skip"], ints["first"], ints["count"], ints["pre_parent"]
    launch(
        _preorder, dim=nodes, device=device,
        inputs=[keys, range_a, range_b, parent, leaf_size, before, int(groups is not None),
                skip, first, count, group_roots, node_first, node_next, int(bottom_up),
                pre_parent],
    )  # fmt: skip
    num_nodes = int(before[n : n + 1].numpy()[0])  # the build's one read back
    if bottom_up:
        pre_parent, arrivals = pre_parent[:num_nodes], zero["arrivals"][:num_nodes]
    else:
        arrivals = pre_parent  # empty
    return DeviceTree(
        skip[:num_nodes], first[:num_nodes], count[:num_nodes], values[:n],
        group_roots[:num_groups], pre_parent, arrivals, num_nodes, packed[:num_nodes],
    )  # fmt: skip


def _carve(block: array, sizes: dict[str, int]) -> dict[str, array]:
    """Consecutive views of the 1-d ``block``, one per entry of ``sizes``."""
    views, at = {}, 0
    for name, size in sizes.items():
        views[name] = block[at : at + size]
        at += size
    return views
