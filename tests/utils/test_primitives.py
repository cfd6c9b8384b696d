"""``kdsl.utils``: scans, sorts, run-length encoding and reductions against NumPy."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.utils import buffers

DEVICES = [
    "cpu",
    pytest.param("cuda:0", marks=pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")),
]
#: Sizes below and above the point where the CPU splits work over threads.
SIZES = [1, 7, 1000, buffers.PARALLEL_MIN * 3 + 5]


@pytest.fixture(autouse=True)
def _two_host_threads(monkeypatch):
    # The CPU paths must be exercised split even on a one-core runner.
    buffers.host_threads.cache_clear()
    monkeypatch.setattr(buffers, "host_threads", lambda: 2)


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("n", SIZES)
@pytest.mark.parametrize("dtype", [np.int32, np.int64, np.float32, np.float64])
@pytest.mark.parametrize("inclusive", [True, False])
def test_scan_matches_cumsum(device, n, dtype, inclusive):
    rng = np.random.default_rng(n)
    x = rng.integers(-50, 50, n).astype(dtype)
    a = wp.array(x, device=device)
    out = wp.empty(n, dtype=a.dtype, device=device)
    wp.utils.array_scan(a, out, inclusive=inclusive)
    want = np.cumsum(x.astype(np.float64))
    if not inclusive:
        want = np.concatenate([[0], want[:-1]])
    np.testing.assert_array_equal(out.numpy(), want.astype(dtype))  # small ints: exact


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("n", SIZES)
def test_exclusive_scan_in_place(device, n):
    # Split over threads, an in-place exclusive scan once read overwritten inputs.
    x = np.random.default_rng(n).integers(0, 3, n).astype(np.int32)
    a = wp.array(x, device=device)
    wp.utils.array_scan(a, a, inclusive=False)
    np.testing.assert_array_equal(a.numpy(), np.concatenate([[0], np.cumsum(x)[:-1]]))


@pytest.mark.parametrize("device", DEVICES)
def test_scan_of_vectors_is_componentwise_and_in_place(device):
    x = np.arange(30, dtype=np.float32).reshape(10, 3)
    a = wp.array(x, dtype=wp.vec3, device=device)
    wp.utils.array_scan(a, a)
    np.testing.assert_array_equal(a.numpy(), np.cumsum(x, axis=0))


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("n", SIZES)
@pytest.mark.parametrize("kdtype", [np.int32, np.uint32, np.float32, np.int64, np.float64])
def test_radix_sort_pairs_is_a_stable_sort(device, n, kdtype):
    rng = np.random.default_rng(n + 1)
    keys = rng.integers(-20, 20, n).astype(kdtype)  # many ties: stability matters
    values = np.arange(n, dtype=np.int32)
    k = wp.array(np.concatenate([keys, keys]), device=device)
    v = wp.array(np.concatenate([values, values]), device=device)
    wp.utils.radix_sort_pairs(k, v, n)
    order = np.argsort(keys, kind="stable")
    np.testing.assert_array_equal(k.numpy()[:n], keys[order])
    np.testing.assert_array_equal(v.numpy()[:n], values[order])
    np.testing.assert_array_equal(k.numpy()[n:], keys)  # beyond count: untouched here


@pytest.mark.parametrize("device", DEVICES)
def test_float_keys_sort_in_radix_order(device):
    keys = np.array([np.nan, 1.0, -0.0, 0.0, -np.inf, -np.nan, np.inf, -1.0], np.float32)
    n = len(keys)
    k = wp.array(np.concatenate([keys, keys]), device=device)
    v = wp.array(np.arange(2 * n, dtype=np.int32), device=device)
    wp.utils.radix_sort_pairs(k, v, n)
    # -NaN first, then -inf .. -1, -0 before +0, .. +inf, NaN last (Warp's and CUB's order).
    assert list(v.numpy()[:n]) == [5, 4, 7, 2, 3, 1, 6, 0]


@pytest.mark.parametrize("device", DEVICES)
def test_sort_on_a_bit_range(device):
    keys = np.array([0x12, 0x21, 0x11, 0x22], np.int32)
    k = wp.array(np.concatenate([keys, keys]), device=device)
    v = wp.array(np.arange(8, dtype=np.int32), device=device)
    wp.utils.radix_sort_pairs(k, v, 4, begin_bit=4, end_bit=8)  # the high nibble only
    assert list(v.numpy()[:4]) == [0, 2, 1, 3]


@pytest.mark.parametrize("device", DEVICES)
def test_segmented_sort_sorts_inside_segments_only(device):
    keys = np.array([5, 4, 3, 9, 8, 7, 2, 1], np.float32)
    n = len(keys)
    k = wp.array(np.concatenate([keys, keys]), device=device)
    v = wp.array(np.arange(2 * n, dtype=np.int32), device=device)
    starts = wp.array(np.array([0, 3, 6], np.int32), device=device)
    ends = wp.array(np.array([3, 5, 6], np.int32), device=device)
    wp.utils.segmented_sort_pairs(k, v, n, starts, ends)
    assert list(k.numpy()[:n]) == [3, 4, 5, 8, 9, 7, 2, 1]
    assert list(v.numpy()[:n]) == [2, 1, 0, 4, 3, 5, 6, 7]
    adjacent = wp.array(np.array([0, 3, 8], np.int32), device=device)
    wp.utils.segmented_sort_pairs(k, v, n, adjacent)
    assert list(k.numpy()[:n]) == [3, 4, 5, 1, 2, 7, 8, 9]


@pytest.mark.parametrize("device", DEVICES)
def test_runlength_encode(device):
    x = np.array([1, 1, 1, 2, 2, 3, 1, 1], np.int32)
    values, lengths = (wp.zeros(8, dtype=wp.int32, device=device) for _ in range(2))
    runs = wp.utils.runlength_encode(wp.array(x, device=device), values, lengths)
    assert runs == 4
    assert list(values.numpy()[:4]) == [1, 2, 3, 1] and list(lengths.numpy()[:4]) == [3, 2, 1, 2]
    count = wp.zeros(1, dtype=wp.int32, device=device)
    out = wp.utils.runlength_encode(wp.array(x, device=device), values, lengths, count, 5)
    assert out is count and count.numpy()[0] == 2
    assert wp.utils.runlength_encode(wp.array(x, device=device), values, lengths,
                                     value_count=0) == 0  # fmt: skip


@pytest.mark.parametrize("device", DEVICES)
def test_sums_and_inner_products(device):
    rng = np.random.default_rng(3)
    x = rng.standard_normal((4, 5))
    y = rng.standard_normal((4, 5))
    a, b = wp.array(x, device=device), wp.array(y, device=device)
    assert wp.utils.array_sum(a) == pytest.approx(x.sum())
    assert wp.utils.array_sum(a, value_count=7) == pytest.approx(x.ravel()[:7].sum())
    # along an axis the result keeps it, of size 1 (Warp's shapes)
    np.testing.assert_allclose(wp.utils.array_sum(a, axis=1).numpy(), x.sum(axis=1, keepdims=True))
    np.testing.assert_allclose(wp.utils.array_sum(a, axis=-2).numpy(), x.sum(axis=0, keepdims=True))
    assert wp.utils.array_inner(a, b) == pytest.approx((x * y).sum())
    np.testing.assert_allclose(wp.utils.array_inner(a, b, axis=0).numpy(),
                               (x * y).sum(axis=0, keepdims=True))  # fmt: skip
    np.testing.assert_allclose(wp.utils.array_sum(a, axis=1, value_count=2).numpy(),
                               x[:, :2].sum(axis=1, keepdims=True))  # fmt: skip
    col = wp.zeros((4, 1), dtype=wp.float64, device=device)
    assert wp.utils.array_sum(a, out=col, axis=1) is col
    np.testing.assert_allclose(col.numpy(), x.sum(axis=1, keepdims=True))
    with pytest.raises(wp.utils.UtilsError, match=r"out must have shape \(4, 1\)"):
        wp.utils.array_sum(a, out=wp.zeros(4, dtype=wp.float64, device=device), axis=1)
    out = wp.zeros(1, dtype=wp.float64, device=device)
    assert wp.utils.array_sum(a, out=out) is out and out.numpy()[0] == pytest.approx(x.sum())


@pytest.mark.parametrize("device", DEVICES)
def test_vector_sums_and_dot_products(device):
    v = np.arange(12, dtype=np.float32).reshape(4, 3)
    a = wp.array(v, dtype=wp.vec3, device=device)
    total = wp.utils.array_sum(a)
    assert isinstance(total, wp.vec3) and list(total) == [18, 22, 26]
    rows = wp.utils.array_sum(a, axis=0)
    assert rows.shape == (1,) and rows.dtype is wp.vec3 and list(rows.numpy()[0]) == [18, 22, 26]
    assert wp.utils.array_inner(a, a) == pytest.approx(float((v * v).sum()))


def test_bad_arguments_are_clear_errors():
    a = wp.zeros(4, dtype=wp.int32)
    f = wp.zeros(4, dtype=wp.float32)
    with pytest.raises(wp.utils.UtilsError, match="sizes differ"):
        wp.utils.array_scan(a, wp.zeros(5, dtype=wp.int32))
    with pytest.raises(RuntimeError, match="dtypes differ"):  # Warp raises RuntimeError too
        wp.utils.array_scan(a, f)
    with pytest.raises(wp.utils.UtilsError, match="2 \\* count"):
        wp.utils.radix_sort_pairs(a, a, 3)
    with pytest.raises(wp.utils.UtilsError, match="begin_bit"):
        wp.utils.radix_sort_pairs(wp.zeros(8, dtype=wp.int32), wp.zeros(8, dtype=wp.int32), 4,
                                  begin_bit=9, end_bit=4)  # fmt: skip
    with pytest.raises(wp.utils.UtilsError, match="overlap"):
        wp.utils.segmented_sort_pairs(wp.zeros(8, dtype=wp.int32), wp.zeros(8, dtype=wp.int32),
                                      4, wp.array(np.array([0, 1], np.int32)),
                                      wp.array(np.array([3, 4], np.int32)))  # fmt: skip
    with pytest.raises(wp.utils.UtilsError, match="outside"):
        wp.utils.segmented_sort_pairs(wp.zeros(8, dtype=wp.int32), wp.zeros(8, dtype=wp.int32),
                                      4, wp.array(np.array([0, 5], np.int32)))  # fmt: skip
    with pytest.raises(wp.utils.UtilsError, match="int32"):
        wp.utils.runlength_encode(f, f, f)
    with pytest.raises(wp.utils.UtilsError, match="float32- and float64"):
        wp.utils.array_sum(a)
    with pytest.raises(IndexError, match="axis 2"):
        wp.utils.array_sum(f, axis=2)
    with pytest.raises(wp.utils.UtilsError, match="kdsl array"):
        wp.utils.array_sum(np.zeros(3))
