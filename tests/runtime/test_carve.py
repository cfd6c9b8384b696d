"""``kdsl.runtime.carve.carve``: typed views of one allocation's parts share its memory,
keep it alive, have the part's dtype, shape and strides, and refuse parts outside the
block or misaligned for their dtype."""

from __future__ import annotations

import gc

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslError
from kdsl.runtime.carve import carve
from kdsl.stdlib.bvh import BvhNode

DEVICES = [
    "cpu",
    pytest.param("cuda:0", marks=pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")),
]


@pytest.mark.parametrize("device", DEVICES)
def test_views_share_the_block(device):
    block = wp.zeros(64, dtype=wp.int32, device=device)
    a, v, m, none = carve(block, [(8, wp.int32, 5), (32, wp.vec3, 2), (64, wp.int32, (2, 3)),
                                  (999, wp.float32, 0)])  # fmt: skip
    assert (a.dtype, a.shape, a.strides) == (wp.int32, (5,), (4,))
    assert (v.dtype, v.shape, v.strides) == (wp.vec3, (2,), (12,))
    assert (m.shape, m.strides, none.shape) == ((2, 3), (12, 4), (0,))
    a.fill_(7)
    v.fill_(wp.vec3(1.0, 2.0, 3.0))
    m.fill_(-1)
    host = block.numpy()
    np.testing.assert_array_equal(host[2:7], 7)
    np.testing.assert_array_equal(host[8:14].view(np.float32), [1, 2, 3, 1, 2, 3])
    np.testing.assert_array_equal(host[16:22], -1)
    assert host[:2].tolist() == [0, 0] and host[22:].tolist() == [0] * 42


@pytest.mark.parametrize("device", DEVICES)
def test_strided_fields_of_structs_and_the_block_kept_alive(device):
    nodes = wp.empty(4, dtype=BvhNode, device=device)
    whole, first = carve(nodes, [(0, BvhNode, 4), (12, wp.int32, 4, (32,))])
    del nodes
    gc.collect()
    first.assign(wp.array(np.arange(4, dtype=np.int32), device=device))
    assert whole.dtype is BvhNode and whole.shape == (4,)
    assert [int(x) for x in whole.numpy()["first"]] == [0, 1, 2, 3]


def test_refuses_parts_outside_or_misaligned():
    block = wp.zeros(8, dtype=wp.int32)
    with pytest.raises(KdslError, match="outside the block's 32 bytes"):
        carve(block, [(24, wp.int32, 3)])
    with pytest.raises(KdslError, match="outside"):
        carve(block, [(-4, wp.int32, 1)])
    with pytest.raises(KdslError, match="not aligned"):
        carve(block, [(2, wp.int32, 1)])
    with pytest.raises(KdslError, match="not aligned"):
        carve(block, [(0, wp.int32, 2, (6,))])
    with pytest.raises(KdslError, match="C-contiguous"):
        carve(block.reshape((2, 4))[:, :2], [(0, wp.int32, 1)])
