"""``kdsl.utils.sort.SortKeys`` and ``kdsl.utils.scan.ScanInto``, the prepared sort and
scan of the lbvh build: the results of ``np.sort`` and ``array_scan`` call after call
(the buffers rewritten between calls), and clear errors for what they cannot do."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.utils import UtilsError, array_scan
from kdsl.utils.scan import ScanInto
from kdsl.utils.sort import SortKeys

DEVICES = [
    "cpu",
    pytest.param("cuda:0", marks=pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")),
]

NUMPY = {wp.int32: np.int32, wp.int64: np.int64, wp.float32: np.float32}


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("n", [1, 5, 70_001])
@pytest.mark.parametrize("dtype", [wp.uint32, wp.uint64])
def test_sort_keys_sorts_in_place_call_after_call(device, n, dtype):
    rng = np.random.default_rng(n)
    np_type = np.uint32 if dtype is wp.uint32 else np.uint64
    keys = wp.empty(n, dtype=dtype, device=device)
    sort = SortKeys(keys)
    for top in (2**20, 2**32 - 1, 2):  # a call after new keys: the same buffer
        host = rng.integers(0, top, n, dtype=np.uint64).astype(np_type)
        if dtype is wp.uint64:
            host |= np_type(top) << np_type(31)  # high bits in play too
        keys.assign(wp.array(host, dtype=dtype, device=device))
        sort()
        np.testing.assert_array_equal(keys.numpy(), np.sort(host))


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("n", [1, 9, 200_003])
@pytest.mark.parametrize("dtype", [wp.int32, wp.int64, wp.float32])
def test_scan_into_is_array_scan(device, n, dtype):
    rng = np.random.default_rng(n)
    values = wp.empty(n, dtype=dtype, device=device)
    out = wp.empty(n, dtype=dtype, device=device)
    want = wp.empty(n, dtype=dtype, device=device)
    scan = ScanInto(values, out)
    for _ in range(2):
        host = rng.integers(-5, 9, n).astype(NUMPY[dtype])
        values.assign(wp.array(host, dtype=dtype, device=device))
        scan()
        array_scan(values, want, inclusive=True)
        assert out.numpy().tobytes() == want.numpy().tobytes()


def test_views_of_one_block_and_errors():
    block = wp.array(np.arange(8, dtype=np.int32))
    ScanInto(block[:4], block[4:])()
    np.testing.assert_array_equal(block.numpy()[4:], [0, 1, 3, 6])
    with pytest.raises(UtilsError, match="distinct"):
        ScanInto(block, block)
    with pytest.raises(UtilsError, match="one size"):
        ScanInto(block[:4], block[3:])
    with pytest.raises(UtilsError, match="same dtype"):
        ScanInto(block, wp.zeros(8, dtype=wp.float32))
    with pytest.raises(UtilsError, match="int32, int64"):
        ScanInto(wp.zeros(4, dtype=wp.uint8), wp.zeros(4, dtype=wp.uint8))
    with pytest.raises(UtilsError, match="contiguous 1-d"):
        ScanInto(wp.zeros(8, dtype=wp.int32)[::2], wp.zeros(4, dtype=wp.int32))
    with pytest.raises(UtilsError, match="kdsl array"):
        ScanInto(np.zeros(4, np.int32), wp.zeros(4, dtype=wp.int32))
    with pytest.raises(UtilsError, match="uint32 or uint64"):
        SortKeys(wp.zeros(4, dtype=wp.int32))
    with pytest.raises(UtilsError, match="uint32 or uint64"):
        SortKeys(wp.zeros(8, dtype=wp.uint64)[::2])
    with pytest.raises(UtilsError, match="kdsl array"):
        SortKeys(np.zeros(4, np.uint64))
