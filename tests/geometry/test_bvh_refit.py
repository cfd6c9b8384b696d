"""The bottom-up BVH refit (a thread per leaf climbing through arrival counters, the GPU
path) against the sequential reverse-preorder refit, run on the CPU's threads so its
fences and counters are exercised here too; cuda on the GPU machine."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import kdsl as wp
from kdsl.geometry.bvh import CONSTRUCTORS
from kdsl.geometry.device_tree import refit, with_parents

cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")


def boxes(rng, n, device):
    c = rng.random((n, 3)).astype(np.float32)
    h = (rng.random((n, 3)) * 0.01).astype(np.float32)
    return (wp.array(c - h, dtype=wp.vec3, device=device),
            wp.array(c + h, dtype=wp.vec3, device=device))  # fmt: skip


def node_bounds(tree, lo, hi):
    out_lo = wp.empty(tree.num_nodes, dtype=wp.vec3, device=lo.device)
    out_hi = wp.empty(tree.num_nodes, dtype=wp.vec3, device=lo.device)
    refit(tree, lo, hi, out_lo, out_hi)
    return out_lo.numpy(), out_hi.numpy()


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
    assert bottom_up.parent.shape[0] == bottom_up.num_nodes
    parent = bottom_up.parent.numpy()
    assert parent[0] == -1 and np.all(parent[1:] < np.arange(1, bottom_up.num_nodes))
    for step in range(3):  # the arrival counters must be ready again after each refit
        if step:
            lo, hi = boxes(rng, 3000, device)
        want = node_bounds(sequential, lo, hi)
        got = node_bounds(bottom_up, lo, hi)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])
        np.testing.assert_array_equal(got[0][0], lo.numpy().min(axis=0))
        np.testing.assert_array_equal(got[1][0], hi.numpy().max(axis=0))
    assert not bottom_up.arrivals.numpy().any()
