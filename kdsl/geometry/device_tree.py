"""A BVH's arrays on its device, and the refit kernels that compute its node bounds.

Every constructor ends in a ``DeviceTree``: the preorder topology ``kdsl.stdlib.bvh``
documents (``skip``, ``first``, ``count``, ``items``, ``group_roots``) on the boxes'
device, plus what a GPU refit needs: ``parent`` (each node's parent, -1 at the root) and
``arrivals``, one counter per node (both empty on a CPU). An inner node ``n``'s children
are ``n + 1`` and ``skip[n + 1]``, so the tree needs no child arrays (its ``first`` is -1
for an inner node; the packed nodes name the right child there, ``inner_first``). The
arrays have
``slots`` entries: the nodes, then (lbvh trees, whose node count stays on the device)
unused slots marked ``first = UNUSED``, which every kernel here skips, so none needs
the node count on the host.

``refit`` runs as kdsl kernels on the device and writes the packed nodes
(``BvhNode``) whole. On a GPU it is one launch, bottom up as Karras and Apetrei build
theirs: a thread per leaf writes the union of its items' boxes, then climbs; at each
parent it fences and bumps the parent's arrival counter, and the second child's thread
to arrive (it fences again, so it sees the first child's bounds) writes the parent's
union and climbs on, while the first stops. The climb is a chain of dependent memory
round trips as long as the tree is deep (24 levels for the benchmark's 200k faces), so
each step does few: the links it needs next (the sibling, the grandparent, the parent's
``skip``) are read before the counter, the arriving thread keeps its own union in
registers and reads only its sibling, a packed node in two 16-byte loads, and writes
the parent whole in two 16-byte stores; the counters are never reset: the second
arrival is the one that finds an odd count, so a refit adds two to each inner node's
counter and leaves them all even (no memset, no reset store). On the H200 this took
the refit of the benchmark mesh's tree from 0.052 to 0.040 ms (session 11,
docs/performance.md). On a CPU, after the leaves, one thread walks the inner nodes in
reverse preorder (children before parents), which beats atomics on a few cores. A
refit can be made conditional on counters on the device (``refit_steps``' ``found``):
a mesh's refit is issued before the host knows whether its points are good.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from kdsl.frontend.api import atomic_add, func, inout, kernel, thread_fence, tid
from kdsl.frontend.api import max as vmax
from kdsl.frontend.api import min as vmin
from kdsl.geometry.median import Tree
from kdsl.runtime.alloc import empty, zeros
from kdsl.runtime.array import array
from kdsl.runtime.carve import carve
from kdsl.runtime.launch import launch
from kdsl.stdlib.bvh import BvhNode, inner_first
from kdsl.types import int32, vec3

#: ``first`` of a node slot past a tree's last node (an lbvh tree has ``2n - 1`` slots
#: and fewer nodes with ``leaf_size > 1``): no node, skipped by the refits.
UNUSED = -2


@dataclass
class DeviceTree:
    """A BVH's topology on its device (see the module docstring), in ``slots`` node
    slots: its nodes, then unused slots (``first`` is ``UNUSED``)."""

    skip: array
    first: array
    count: array
    items: array
    group_roots: array
    parent: array  # empty on a CPU
    arrivals: array  # int32 per slot, even between refits; empty on a CPU
    slots: int
    #: The packed nodes (``kdsl.stdlib.bvh.BvhNode``) with their links written, when the
    #: constructor wrote them itself (``lbvh``); None: ``kdsl.Bvh`` packs them.
    nodes: array | None = None
    #: ``node_views(nodes)``, when the constructor made them.
    views: tuple | None = None
    #: A one-element int32 array on the device holding the number of nodes, when the
    #: constructor left it there (None: ``slots`` nodes).
    node_count: array | None = None
    #: Whether the constructor wrote the packed nodes' bounds too (no refit needed).
    bounded: bool = False
    #: A one-element int32 array on the device: the tree's height (the most levels
    #: below the root; 0 for a leaf root), which bounds the entries a walk's stack
    #: holds. None for an empty tree.
    height: array | None = None
    #: Builds the same tree arrays again from the boxes' current values, when the
    #: constructor can (``lbvh``); None otherwise.
    rebuild: Callable[[], object] | None = None
    _num_nodes: int | None = field(default=None, init=False, repr=False)

    @property
    def num_nodes(self) -> int:
        """The number of nodes (read back from the device once per build when the
        constructor left it there: for tests and tools, not the build)."""
        if self._num_nodes is None:
            self._num_nodes = (
                self.slots if self.node_count is None else int(self.node_count.numpy()[0])
            )
        return self._num_nodes

    def forget_count(self) -> None:
        """Drop the node count read back before a rebuild."""
        self._num_nodes = None


#: The fields of a packed node (``BvhNode``): (byte offset, dtype).
_NODE_FIELDS = ((0, vec3), (12, int32), (16, vec3), (28, int32))


def node_fields(slots: int, at: int = 0) -> list[tuple]:
    """The ``carve`` parts of ``node_views`` over ``slots`` packed nodes starting ``at``
    bytes into a block."""
    return [(at + offset, t, slots, (32,)) for offset, t in _NODE_FIELDS]


def node_views(nodes: array) -> tuple[array, array, array, array]:
    """Strided views of the fields of every packed node (``BvhNode``, a contiguous
    array): ``lower`` (vec3), ``first`` (int32), ``upper`` (vec3), ``next`` (int32)."""
    return tuple(carve(nodes, node_fields(nodes.shape[0])))


def _device_ints(a: np.ndarray, device) -> array:
    return array(np.ascontiguousarray(a, dtype=np.int32), dtype=int32, device=device)


@kernel
def _link_parents(first: array(dtype=int32), skip: array(dtype=int32), parent: array(dtype=int32)):
    n = tid()
    if n == 0:
        parent[0] = -1
    if first[n] == -1:  # an inner node (not an unused slot)
        parent[n + 1] = n
        parent[skip[n + 1]] = n


def with_parents(tree: DeviceTree, bottom_up: bool | None = None) -> DeviceTree:
    """``tree`` with the arrays of the bottom-up refit (``parent``, ``arrivals``) filled
    in: on a GPU by default, anywhere with ``bottom_up=True``."""
    device = tree.skip.device
    if not (device.is_cuda if bottom_up is None else bottom_up) or tree.slots == 0:
        return tree
    tree.parent = empty(tree.slots, dtype=int32, device=device)
    tree.arrivals = zeros(tree.slots, dtype=int32, device=device)
    launch(_link_parents, dim=tree.slots, device=device,
           inputs=[tree.first, tree.skip, tree.parent])  # fmt: skip
    return tree


def upload_tree(tree: Tree, device) -> DeviceTree:
    """A host-built ``Tree`` copied to ``device``."""
    none = _device_ints(np.zeros(0), device)
    return with_parents(DeviceTree(
        _device_ints(tree.skip, device), _device_ints(tree.first, device),
        _device_ints(tree.count, device), _device_ints(tree.items, device),
        _device_ints(tree.group_roots, device), none, none, tree.num_nodes,
        height=_device_ints(np.array([tree.level.max(initial=0)]), device),
    ))  # fmt: skip


@func
def _leaf_bounds(
    f: int, count: int, items: array(dtype=int32), item_lowers: array(dtype=vec3),
    item_uppers: array(dtype=vec3), lo: inout(vec3), hi: inout(vec3),
):  # fmt: skip
    """The union of the boxes of ``items[f : f + count]`` into ``lo``/``hi``."""
    k = items[f]
    lo = item_lowers[k]
    hi = item_uppers[k]
    for j in range(f + 1, f + count):
        k = items[j]
        lo = vmin(lo, item_lowers[k])
        hi = vmax(hi, item_uppers[k])


@func
def any_set(found: array(dtype=int32)) -> bool:
    """Whether any of ``found``'s (few) counters is not zero."""
    hit = False
    for k in range(found.shape[0]):
        if found[k] != 0:
            hit = True
    return hit


@kernel
def _refit_leaves(
    first: array(dtype=int32), count: array(dtype=int32), items: array(dtype=int32),
    item_lowers: array(dtype=vec3), item_uppers: array(dtype=vec3),
    skip: array(dtype=int32), parent: array(dtype=int32), arrivals: array(dtype=int32),
    found: array(dtype=int32), nodes: array(dtype=BvhNode),
):  # fmt: skip
    # Thread n: leaf n's bounds from its items' boxes, then, when the tree has parent
    # links, the climb (see the module docstring). Nothing when ``found`` has a count.
    n = tid()
    f = first[n]
    if f < 0 or any_set(found):
        return
    lo = vec3()
    hi = vec3()
    c = count[n]
    _leaf_bounds(f, c, items, item_lowers, item_uppers, lo, hi)
    nodes[n] = BvhNode(lo, f, hi, c)  # (whole: two 16-byte stores; the links as they are)
    if parent.shape[0] == 0:
        return
    p = parent[n]
    while p >= 0:
        s = p + 1  # the sibling: the parent's other child
        if s == n:
            s = skip[s]
        up = parent[p]  # (the links read now: not behind the counter)
        next_p = skip[p]
        thread_fence()  # publish this child's bounds before its arrival
        if (atomic_add(arrivals, p, 1) & 1) == 0:
            return  # the sibling's thread, arriving second, completes ``p``
        thread_fence()  # see the sibling's bounds, published before its arrival
        sibling = nodes[s]  # (two 16-byte loads)
        lo = vmin(lo, sibling.lower)
        hi = vmax(hi, sibling.upper)
        nodes[p] = BvhNode(lo, inner_first(vmax(n, s)), hi, next_p)  # (right: the later)
        n = p
        p = up


@kernel
def _pack_links(
    first: array(dtype=int32), count: array(dtype=int32), skip: array(dtype=int32),
    packed_first: array(dtype=int32), packed_next: array(dtype=int32),
):  # fmt: skip
    n = tid()
    f = first[n]
    packed_first[n] = f
    if f >= 0:
        packed_next[n] = count[n]
    else:
        packed_next[n] = skip[n]
        if f == -1:  # an inner node (not an unused slot): its right child
            packed_first[n] = inner_first(skip[n + 1])


def pack_nodes(tree: DeviceTree, views: tuple) -> None:
    """Write the links of the packed nodes whose ``node_views`` are ``views``: ``first``
    (a leaf's, or an inner node's right child as ``inner_first``), and ``next``, an inner
    node's ``skip`` or a leaf's count; ``refit`` writes the bounds."""
    if tree.slots == 0:
        return
    launch(_pack_links, dim=tree.slots, device=views[1].device,
           inputs=[tree.first, tree.count, tree.skip, views[1], views[3]])  # fmt: skip


@kernel
def _refit_inner_reverse_preorder(
    slots: int32, first: array(dtype=int32), skip: array(dtype=int32),
    found: array(dtype=int32), nodes: array(dtype=BvhNode),
):  # fmt: skip
    # One thread: in reverse preorder every node comes after its children.
    if any_set(found):
        return
    for k in range(slots):
        n = slots - 1 - k
        if first[n] == -1:  # an inner node (not an unused slot)
            r = skip[n + 1]  # the right child
            a = nodes[n + 1]
            b = nodes[r]
            nodes[n] = BvhNode(vmin(a.lower, b.lower), inner_first(r), vmax(a.upper, b.upper),
                               skip[n])  # fmt: skip


def refit_steps(tree: DeviceTree, item_lowers: array, item_uppers: array, nodes: array,
                found: array | None = None,
                prepared: bool = True) -> list[Callable[[], object]]:  # fmt: skip
    """The launches (callables) that write the bounds of ``tree``'s packed nodes ``nodes``
    (``BvhNode``, links already packed) over the item boxes: bottom up where the tree
    has ``parent`` links (on a GPU), else the leaves then a sequential pass (see the
    module docstring). With ``found`` (a few int32 counters on the device, written
    before the steps run), they write nothing when one is not zero. ``prepared``: the
    launches recorded once (``record_cmd``), else plain launches each call (what an open
    graph capture records)."""
    if tree.slots == 0:
        return []
    device = item_lowers.device
    if found is None:
        found = tree.parent[:0]
    runs = [
        (_refit_leaves, tree.slots, [tree.first, tree.count, tree.items, item_lowers,
                                     item_uppers, tree.skip, tree.parent, tree.arrivals,
                                     found, nodes]),
    ]  # fmt: skip
    if tree.parent.shape[0] == 0:
        runs.append((_refit_inner_reverse_preorder, 1,
                     [tree.slots, tree.first, tree.skip, found, nodes]))  # fmt: skip
    if not prepared:
        return [functools.partial(launch, k, dim=dim, device=device, inputs=inputs)
                for k, dim, inputs in runs]  # fmt: skip
    return [launch(k, dim=dim, device=device, inputs=inputs, record_cmd=True).launch
            for k, dim, inputs in runs]  # fmt: skip


def refit(tree: DeviceTree, item_lowers: array, item_uppers: array, nodes: array) -> None:
    """Write the bounds of ``tree``'s packed nodes over the item boxes once (see
    ``refit_steps``)."""
    for step in refit_steps(tree, item_lowers, item_uppers, nodes):
        step()
