"""A BVH's arrays on its device, and the refit kernels that compute its node bounds.

Every constructor ends in a ``DeviceTree``: the preorder topology ``kdsl.stdlib.bvh``
documents (``skip``, ``first``, ``count``, ``items``, ``group_roots``) on the boxes'
device, plus what a GPU refit needs: ``by_level``, the inner nodes ordered deepest level
first, and ``levels``, the ``(start, count)`` of each level in it (on the host, so a
refit reads nothing back from a GPU; both empty on a CPU). An inner node ``n``'s children are ``n + 1`` and
``skip[n + 1]``, so the tree needs no child arrays.

``refit`` runs as kdsl kernels on the device: on a GPU one launch for the leaves (the
union of their items' boxes), then one per level of inner nodes, deepest first, each
the union of its two children (a level's nodes are independent, so no atomics or
fences); on a CPU, after the leaves, one thread walks the inner nodes in reverse
preorder (children before parents), which costs less than a launch per level.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kdsl.frontend.api import kernel, tid
from kdsl.frontend.api import max as vmax
from kdsl.frontend.api import min as vmin
from kdsl.geometry.median import Tree
from kdsl.runtime.array import array
from kdsl.runtime.launch import launch
from kdsl.types import int32, vec3


@dataclass
class DeviceTree:
    """A BVH's topology on its device (see the module docstring)."""

    skip: array
    first: array
    count: array
    items: array
    group_roots: array
    by_level: array
    levels: list[tuple[int, int]]  # (start, count) in ``by_level``, deepest level first
    num_nodes: int


def _device_ints(a: np.ndarray, device) -> array:
    return array(np.ascontiguousarray(a, dtype=np.int32), dtype=int32, device=device)


def level_order(first: np.ndarray, depth: np.ndarray, device) -> tuple[array, list]:
    """``by_level`` (on ``device``) and ``levels`` of a tree from its nodes' ``first`` and
    depth (host arrays)."""
    inner = np.flatnonzero(first < 0)
    d = depth[inner]
    deepest = int(d.max(initial=-1))
    # A radix sort (NumPy sorts 16-bit keys by radix) of the depths, deepest first.
    key = (deepest - d).astype(np.uint16 if deepest < 1 << 16 else np.int64)
    by_level = inner[np.argsort(key, kind="stable")]
    counts = np.bincount(key, minlength=deepest + 1)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    levels = [(int(s), int(c)) for s, c in zip(starts, counts) if c]
    return _device_ints(by_level, device), levels


def upload_tree(tree: Tree, device) -> DeviceTree:
    """A host-built ``Tree`` copied to ``device``."""
    if device.is_cpu:  # a CPU refit needs no levels (``refit``)
        by_level, levels = _device_ints(np.zeros(0), device), []
    else:
        by_level, levels = level_order(tree.first, tree.level, device)
    return DeviceTree(
        _device_ints(tree.skip, device), _device_ints(tree.first, device),
        _device_ints(tree.count, device), _device_ints(tree.items, device),
        _device_ints(tree.group_roots, device), by_level, levels, tree.num_nodes,
    )  # fmt: skip


@kernel
def _refit_leaves(
    first: array(dtype=int32), count: array(dtype=int32),
    items: array(dtype=int32), item_lowers: array(dtype=vec3),
    item_uppers: array(dtype=vec3), lowers: array(dtype=vec3),
    uppers: array(dtype=vec3),
):  # fmt: skip
    n = tid()
    f = first[n]
    if f >= 0:
        k = items[f]
        lo = item_lowers[k]
        hi = item_uppers[k]
        for j in range(f + 1, f + count[n]):
            k = items[j]
            lo = vmin(lo, item_lowers[k])
            hi = vmax(hi, item_uppers[k])
        lowers[n] = lo
        uppers[n] = hi


@kernel
def _refit_level(
    by_level: array(dtype=int32), start: int32, skip: array(dtype=int32),
    lowers: array(dtype=vec3), uppers: array(dtype=vec3),
):  # fmt: skip
    n = by_level[start + tid()]
    a = n + 1
    b = skip[a]
    lowers[n] = vmin(lowers[a], lowers[b])
    uppers[n] = vmax(uppers[a], uppers[b])


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


def pack_nodes(tree: DeviceTree, nodes: array, packed_first: array) -> None:
    """Write the links of the packed nodes (``kdsl.stdlib.bvh.BvhNode``): ``first``, and
    ``next``, an inner node's ``skip`` or a leaf's count; ``refit`` writes the bounds."""
    if tree.num_nodes == 0:
        return
    packed_next = array(ptr=nodes.ptr + 28, dtype=int32, shape=nodes.shape,
                        strides=nodes.strides, device=nodes.device)  # fmt: skip
    launch(_pack_links, dim=tree.num_nodes, device=nodes.device,
           inputs=[tree.first, tree.count, tree.skip, packed_first, packed_next])  # fmt: skip


@kernel
def _refit_inner_reverse_preorder(
    num_nodes: int32, first: array(dtype=int32), skip: array(dtype=int32),
    lowers: array(dtype=vec3), uppers: array(dtype=vec3),
):  # fmt: skip
    # One thread: in reverse preorder every node comes after its children.
    for k in range(num_nodes):
        n = num_nodes - 1 - k
        if first[n] < 0:
            a = n + 1
            b = skip[a]
            lowers[n] = vmin(lowers[a], lowers[b])
            uppers[n] = vmax(uppers[a], uppers[b])


def refit(tree: DeviceTree, item_lowers: array, item_uppers: array, lowers: array,
          uppers: array) -> None:  # fmt: skip
    """Write the node bounds of ``tree`` over the item boxes into ``lowers``/``uppers``."""
    if tree.num_nodes == 0:
        return
    device = item_lowers.device
    launch(
        _refit_leaves, dim=tree.num_nodes, device=device,
        inputs=[tree.first, tree.count, tree.items, item_lowers, item_uppers, lowers, uppers],
    )  # fmt: skip
    if device.is_cpu:  # one sequential pass beats a launch per level on a CPU
        launch(_refit_inner_reverse_preorder, dim=1, device=device,
               inputs=[tree.num_nodes, tree.first, tree.skip, lowers, uppers])  # fmt: skip
        return
    for start, count in tree.levels:
        launch(
            _refit_level, dim=count, device=device,
            inputs=[tree.by_level, start, tree.skip, lowers, uppers],
        )  # fmt: skip
