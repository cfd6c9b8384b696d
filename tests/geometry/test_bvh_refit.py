"""The bottom-up BVH refit (a thread per leaf climbing through arrival counters, the GPU
path) against the sequential reverse-preorder refit, run on the CPU's threads so its
fences and counters are exercised here too; cuda on the GPU machine."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import kdsl as wp
from kdsl.geometry.bvh import CONSTRUCTORS
from kdsl.geometry.device_tree import UNUSED, node_views, pack_nodes, refit, with_parents
from kdsl.geometry.lbvh import build_lbvh
from kdsl.stdlib.bvh import BvhNode

cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")


def boxes(rng, n, device):
    c = rng.random((n, 3)).astype(np.float32)
    h = (rng.random((n, 3)) * 0.01).astype(np.float32)
    return (wp.array(c - h, dtype=wp.vec3, device=device),
            wp.array(c + h, dtype=wp.vec3, device=device))  # fmt: skip


def node_bounds(tree, lo, hi):
    nodes = wp.empty(tree.slots, dtype=BvhNode, device=lo.device)
    pack_nodes(tree, node_views(nodes))
    refit(tree, lo, hi, nodes)
    got = nodes.numpy()[: tree.num_nodes]
    packed = wp.empty(tree.slots, dtype=BvhNode, device=lo.device)
    pack_nodes(tree, node_views(packed))  # the refit writes the links as they were
    want = packed.numpy()[: tree.num_nodes]
    np.testing.assert_array_equal(got["first"], want["first"])
    np.testing.assert_array_equal(got["next"], want["next"])
    np.testing.assert_array_equal(got["first"], right_linked_first(tree))
    return got["lower"], got["upper"]


def right_linked_first(tree):
    """The packed ``first`` of ``tree``'s nodes, from its topology: a leaf's first item,
    an inner node's ``-1 - right`` (its right child ``skip[n + 1]``)."""
    m = tree.num_nodes
    first, skip = tree.first.numpy()[:m], tree.skip.numpy()
    inner = np.flatnonzero(first == -1)
    out = first.copy()
    out[inner] = -1 - skip[inner + 1]
    assert np.all(out[inner] <= -3) and np.all(out[first != -1] >= 0)  # (apart from UNUSED)
    return out


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda:0", marks=cuda)])
@pytest.mark.parametrize("constructor", sorted(CONSTRUCTORS))
@pytest.mark.parametrize("leaf_size", [1, 4])
def test_bottom_up_refit_matches_sequential(device, constructor, leaf_size):
    rng = np.random.default_rng(7)
    lo, hi = boxes(rng, 3000, device)
    build = CONSTRUCTORS[constructor]
    tree = build(lo, hi, leaf_size, None, 0)
    none = wp.empty(0, dtype=wp.int32, device=device)  # no parent links: the sequential pass
    sequential = dataclasses.replace(tree, parent=none, arrivals=none)
    bottom_up = with_parents(build(lo, hi, leaf_size, None, 0), bottom_up=True)
    assert bottom_up.parent.shape[0] == bottom_up.slots >= bottom_up.num_nodes
    parent = bottom_up.parent.numpy()[: bottom_up.num_nodes]  # then unused slots (lbvh)
    assert parent[0] == -1 and np.all(parent[1:] < np.arange(1, bottom_up.num_nodes))
    for step in range(3):  # the arrival counters must be ready (even) after each refit
        if step:
            lo, hi = boxes(rng, 3000, device)
        want = node_bounds(sequential, lo, hi)
        got = node_bounds(bottom_up, lo, hi)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])
        np.testing.assert_array_equal(got[0][0], lo.numpy().min(axis=0))
        np.testing.assert_array_equal(got[1][0], hi.numpy().max(axis=0))
    arrivals = bottom_up.arrivals.numpy()
    assert not (arrivals & 1).any()  # each refit adds two to every inner node's
    inner = bottom_up.first.numpy() == -1
    np.testing.assert_array_equal(arrivals[inner], 6)
    assert not arrivals[~inner].any()


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda:0", marks=cuda)])
@pytest.mark.parametrize("leaf_size", [1, 3])
@pytest.mark.parametrize("num_groups", [0, 5])
def test_lbvh_writes_the_parents_and_links_of_its_nodes(device, leaf_size, num_groups):
    """The lbvh build numbers each node's parent and packs each node's links itself (no
    separate launches): the same as ``with_parents`` and ``pack_nodes`` give."""
    rng = np.random.default_rng(11)
    lo, hi = boxes(rng, 2000, device)
    groups = None
    if num_groups:
        groups = wp.array(rng.integers(0, num_groups, 2000).astype(np.int32), device=device)
    tree = build_lbvh(lo, hi, leaf_size, groups, num_groups, bottom_up=True)
    none = wp.empty(0, dtype=wp.int32, device=device)
    linked = with_parents(dataclasses.replace(tree, parent=none, arrivals=none), bottom_up=True)
    m = tree.num_nodes  # the nodes, then unused slots
    np.testing.assert_array_equal(tree.parent.numpy()[:m], linked.parent.numpy()[:m])
    assert tree.arrivals.shape == (tree.slots,) and not tree.arrivals.numpy().any()
    assert tree.slots == 2 * 2000 - 1 and np.all(tree.first.numpy()[m:] == UNUSED)
    packed = wp.empty(tree.slots, dtype=BvhNode, device=device)
    pack_nodes(tree, node_views(packed))
    got, want = tree.nodes.numpy(), packed.numpy()
    np.testing.assert_array_equal(got["next"][:m], want["next"][:m])
    np.testing.assert_array_equal(got["first"], want["first"])  # (unused slots: UNUSED)
    np.testing.assert_array_equal(got["first"][:m], right_linked_first(tree))
    assert not build_lbvh(lo, hi, leaf_size, groups, num_groups, bottom_up=False).parent.size


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda:0", marks=cuda)])
def test_a_captured_refit_replays(device):
    """``Bvh.refit`` prepares its launches once, but inside an open graph capture it
    launches plainly, so the capture records the refit and each replay refits."""
    rng = np.random.default_rng(5)
    lo, hi = boxes(rng, 500, device)
    bvh = wp.Bvh(lo, hi)
    bvh.refit()  # (prepared outside the capture)
    with wp.ScopedCapture(device=device) as capture:
        bvh.refit()
    for shift in (0.5, -0.25):
        moved = lo.numpy() - shift
        wp.copy(lo, wp.array(moved, dtype=wp.vec3, device=device))
        wp.capture_launch(capture.graph)
        wp.synchronize_device(device)
        np.testing.assert_array_equal(bvh._nodes.numpy()[0]["lower"], moved.min(axis=0))
