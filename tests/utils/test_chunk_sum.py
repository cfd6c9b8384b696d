"""``kdsl.utils.chunk_sum.ChunkSum``: a prepared sum as kdsl kernels, in a fixed order of
additions (bit for bit a float32 emulation of it), skipped by a nonzero guard, and
refusing what it cannot sum."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.utils import UtilsError
from kdsl.utils.chunk_sum import CHUNK, ChunkSum, scratch_size, sum_levels

DEVICES = [
    "cpu",
    pytest.param("cuda:0", marks=pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")),
]


def emulated(values: np.ndarray, chunk: int = CHUNK) -> np.float32:
    """The sum in ChunkSum's order: chunks of ``chunk`` added left to right, level by level."""
    v = values.astype(np.float32)
    while True:
        pad = (-len(v)) % chunk if len(v) else chunk
        rows = np.concatenate([v, np.zeros(pad, np.float32)]).reshape(-1, chunk)
        v = np.cumsum(rows, axis=1, dtype=np.float32)[:, -1]  # (cumsum adds in order)
        if len(v) == 1:
            return v[0]


def test_levels():
    assert sum_levels(0) == [1] and sum_levels(1) == [1] and sum_levels(64) == [1]
    assert sum_levels(65) == [2, 1]
    assert sum_levels(200_000) == [3125, 49, 1]
    assert scratch_size(200_000) == 3174 and scratch_size(64) == 0


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("n", [0, 1, 63, 64, 65, 4097, 300_001])
def test_the_order_of_its_additions(device, n):
    rng = np.random.default_rng(n)
    host = (rng.random(n) * 100 - 20).astype(np.float32)
    values = wp.array(host, dtype=wp.float32, device=device)
    out = wp.full(1, -1.0, dtype=wp.float32, device=device)
    total = ChunkSum(values, out)
    total()
    got = out.numpy()[0]
    assert got.tobytes() == emulated(host).tobytes()
    np.testing.assert_allclose(got, host.astype(np.float64).sum(), rtol=1e-5, atol=1e-3)
    values.assign(wp.array(host * 2, dtype=wp.float32, device=device))  # summed again
    total()
    assert out.numpy()[0] == emulated(host * 2)


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("n", [0, 7, 26, 1000])
def test_other_chunk_sizes(device, n):
    host = np.random.default_rng(n).random(n).astype(np.float32)
    out = wp.full(1, -1.0, dtype=wp.float32, device=device)
    ChunkSum(wp.array(host, dtype=wp.float32, device=device), out, chunk=5)()
    assert out.numpy()[0].tobytes() == emulated(host, 5).tobytes()


@pytest.mark.parametrize("device", DEVICES)
def test_a_nonzero_guard_skips_the_write(device):
    values = wp.array(np.arange(1000, dtype=np.float32), device=device)
    block = wp.full(3, 7.0, dtype=wp.float32, device=device)  # out, then two guard slots
    guard = block[1:].view(wp.int32)
    guard.zero_()
    total = ChunkSum(values, block[:1], guard=guard)
    total()
    assert block.numpy()[0] == 499500.0
    values.assign(wp.array(np.ones(1000, np.float32), device=device))
    guard.assign(wp.array(np.array([0, 5], np.int32), device=device))
    total()
    assert block.numpy()[0] == 499500.0  # left as it was
    guard.zero_()
    total()
    assert block.numpy()[0] == 1000.0


def test_refuses_what_it_cannot_sum():
    f = wp.zeros(1, dtype=wp.float32)
    with pytest.raises(UtilsError, match="contiguous 1-d float32"):
        ChunkSum(wp.zeros(4, dtype=wp.float64), f)
    with pytest.raises(UtilsError, match="contiguous 1-d float32"):
        ChunkSum(wp.zeros((2, 2), dtype=wp.float32), f)
    with pytest.raises(UtilsError, match="at least one element"):
        ChunkSum(wp.zeros(4, dtype=wp.float32), wp.zeros(0, dtype=wp.float32))
    with pytest.raises(UtilsError, match="guard"):
        ChunkSum(wp.zeros(4, dtype=wp.float32), f, guard=wp.zeros(2, dtype=wp.float32))
    with pytest.raises(UtilsError, match="chunk"):
        ChunkSum(wp.zeros(4, dtype=wp.float32), f, chunk=1)
    with pytest.raises(UtilsError, match="must be a kdsl array"):
        ChunkSum(np.zeros(4, np.float32), f)
    with pytest.raises(UtilsError, match="scratch is 2 float32 at least"):
        ChunkSum(wp.zeros(100, dtype=wp.float32), f, scratch=wp.zeros(1, dtype=wp.float32))


@pytest.mark.parametrize("device", DEVICES)
def test_scratch_given(device):
    """The scratch may be a view of the caller's block (a mesh keeps it with its boxes)."""
    block = wp.zeros(5000 + 1 + scratch_size(5000), dtype=wp.float32, device=device)
    host = np.random.default_rng(1).random(5000).astype(np.float32)
    block[:5000].assign(wp.array(host, device=device))
    ChunkSum(block[:5000], block[5000:5001], scratch=block[5001:])()
    assert block.numpy()[5000] == emulated(host)
