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

from kdsl.frontend.api import atomic_add, func, kernel, tid
from kdsl.frontend.api import max as vmax
from kdsl.frontend.api import min as vmin
from kdsl.geometry.device_tree import DeviceTree, node_field
from kdsl.runtime.alloc import empty, full, zeros
from kdsl.runtime.array import array
from kdsl.runtime.launch import launch
from kdsl.stdlib.bvh import BvhNode
from kdsl.types import int32, uint64, vec3
from kdsl.utils import array_scan, radix_sort_pairs

#: Boxes a thread reduces per pass of the centres' bounds, per device kind: on a GPU few
#: (many threads, a pass or two more), on a CPU many (one chunk per core's share).
_CHUNK = {"cuda": 64, "cpu": 1024}


@kernel
def _bounds_pass(
    lowers: array(dtype=vec3), uppers: array(dtype=vec3), n: int32, chunk: int32,
    centres: int32, part_lo: array(dtype=vec3), part_hi: array(dtype=vec3),
):  # fmt: skip
    # The bounds of chunk ``tid()`` of the boxes (of their centres, with ``centres``).
    t = tid()
    begin = t * chunk
    lo = lowers[begin]
    hi = uppers[begin]
    if centres != 0:
        lo = 0.5 * (lo + hi)
        hi = lo
    for i in range(begin + 1, vmin(begin + chunk, n)):
        box_lo = lowers[i]
        box_hi = uppers[i]
        if centres != 0:
            box_lo = 0.5 * (box_lo + box_hi)
            box_hi = box_lo
        lo = vmin(lo, box_lo)
        hi = vmax(hi, box_hi)
    part_lo[t] = lo
    part_hi[t] = hi


def _centre_bounds(lowers: array, uppers: array) -> tuple[array, array]:
    """One-element arrays holding the bounds of the boxes' centres, reduced on the device
    in passes of ``_CHUNK`` boxes a thread."""
    device = lowers.device
    chunk = _CHUNK["cuda" if device.is_cuda else "cpu"]
    lo, hi, n, centres = lowers, uppers, lowers.shape[0], 1
    while True:
        parts = -(-n // chunk)
        part_lo = empty(parts, dtype=vec3, device=device)
        part_hi = empty(parts, dtype=vec3, device=device)
        launch(_bounds_pass, dim=parts, device=device,
               inputs=[lo, hi, n, chunk, centres, part_lo, part_hi])  # fmt: skip
        if parts == 1:
            return part_lo, part_hi
        lo, hi, n, centres = part_lo, part_hi, parts, 0


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
    bounds_lo: array(dtype=vec3), bounds_hi: array(dtype=vec3),
    groups: array(dtype=int32), has_groups: int32,
    keys: array(dtype=uint64), values: array(dtype=int32),
):  # fmt: skip
    i = tid()
    c = 0.5 * (lowers[i] + uppers[i])
    lo = bounds_lo[0]
    extent = bounds_hi[0] - lo
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
):  # fmt: skip
    # Also counts the kept nodes by their first position ``a`` into ``starts[a + 1]``
    # (zeros before): the root, and both children of every inner node that is no leaf.
    i = tid()
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
    counters."""
    device = lowers.device
    n = lowers.shape[0]
    leaf_size = max(1, int(leaf_size))

    def ints(size: int) -> array:  # every element is written before it is read
        return empty(size, dtype=int32, device=device)

    if n == 0:
        none = ints(0)
        return DeviceTree(none, none, none, none, full(num_groups, -1, dtype=int32,
                          device=device), none, none, 0)  # fmt: skip
    bounds_lo, bounds_hi = _centre_bounds(lowers, uppers)
    keys = empty(2 * n, dtype=uint64, device=device)
    values = empty(2 * n, dtype=int32, device=device)
    group_arg = groups if groups is not None else ints(1)
    launch(
        _morton_keys, dim=n, device=device,
        inputs=[lowers, uppers, bounds_lo, bounds_hi, group_arg, int(groups is not None), keys,
                values],
    )  # fmt: skip
    # Only the Morton code's 30 bits and the group id's bits above bit 32 decide the order.
    key_bits = 32 + max(num_groups - 1, 0).bit_length() if groups is not None else 30
    radix_sort_pairs(keys, values, n, end_bit=key_bits)
    nodes = 2 * n - 1
    range_a, range_b, parent = ints(nodes), ints(nodes), ints(nodes)
    counts = zeros(n + 1, dtype=int32, device=device)  # kept nodes starting at a, at a + 1
    launch(_karras_nodes, dim=nodes, device=device,
           inputs=[keys, n, leaf_size, range_a, range_b, parent, counts])  # fmt: skip
    before = ints(n + 1)  # kept nodes starting before each position
    array_scan(counts, before, inclusive=True)
    # The packed nodes, allocated for the most nodes (the count comes back below).
    packed = empty(nodes, dtype=BvhNode, device=device)
    node_first, node_next = node_field(packed, 12, int32), node_field(packed, 28, int32)
    skip, first, count = ints(nodes), ints(nodes), ints(nodes)
    if bottom_up is None:  # a GPU refits bottom up (``device_tree``), from parents
        bottom_up = device.is_cuda
    pre_parent = ints(nodes if bottom_up else 0)
    group_roots = full(max(num_groups, 1), -1, dtype=int32, device=device)
    launch(
        _preorder, dim=nodes, device=device,
        inputs=[keys, range_a, range_b, parent, leaf_size, before, int(groups is not None),
                skip, first, count, group_roots, node_first, node_next, int(bottom_up),
                pre_parent],
    )  # fmt: skip
    num_nodes = int(before[n : n + 1].numpy()[0])  # the build's one read back
    if num_groups == 0:
        group_roots = group_roots[:0]
    none = ints(0)
    arrivals = zeros(num_nodes, dtype=int32, device=device) if bottom_up else none
    return DeviceTree(
        skip[:num_nodes], first[:num_nodes], count[:num_nodes], values[:n], group_roots,
        pre_parent[:num_nodes] if bottom_up else none, arrivals, num_nodes, packed[:num_nodes],
    )  # fmt: skip
