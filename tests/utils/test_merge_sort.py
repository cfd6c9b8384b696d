"""``kdsl.utils.merge_sort.MergeSortKeys``, the kdsl-kernel sort of the GPU lbvh build:
``np.sort``'s result call after call on interp, cpu (and cuda on the GPU machine) for
counts around the chunk and run sizes, duplicates and the full 64-bit range; the
number of launches; the kernels compiled for CUDA (compile only); clear errors."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.utils import UtilsError, merge_sort
from kdsl.utils.merge_sort import MergeSortKeys, merge_passes

DEVICES = [
    "cpu",
    pytest.param("cuda:0", marks=pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")),
]


def keys_of(rng, n: int, kind: str) -> np.ndarray:
    if kind == "full":  # the whole 64-bit range, the top bit too
        return rng.integers(0, 2**64 - 1, n, dtype=np.uint64, endpoint=True)
    if kind == "dups":
        return rng.integers(0, 4, n).astype(np.uint64)
    return np.arange(n, dtype=np.uint64)[::-1].copy()  # descending: every insertion shifts


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("n", [0, 1, 2, 15, 16, 17, 47, 1000, 70_001])
@pytest.mark.parametrize("chunk", [1, 3, merge_sort.CHUNK])
def test_sorts_in_place_call_after_call(device, n, chunk):
    rng = np.random.default_rng(n + chunk)
    keys = wp.empty(n, dtype=wp.uint64, device=device)
    sort = MergeSortKeys(keys, wp.empty(n, dtype=wp.uint64, device=device), chunk)
    for kind in ("full", "dups", "descending"):
        host = keys_of(rng, n, kind)
        keys.assign(wp.array(host, dtype=wp.uint64, device=device))
        sort()
        np.testing.assert_array_equal(keys.numpy(), np.sort(host), err_msg=kind)


def test_kernels_sort_on_the_interpreter():
    """The two kernels, run by the interpreter backend the way the sort runs them."""
    host = keys_of(np.random.default_rng(2), 37, "full")
    src, dst = wp.array(host, dtype=wp.uint64), wp.empty(37, dtype=wp.uint64)
    wp.launch(merge_sort._sort_chunks, dim=10, inputs=[src, dst, 37, 4], backend="interp")
    run = 4
    while run < 37:
        wp.launch(merge_sort._merge_runs, dim=37, inputs=[dst, src, 37, run], backend="interp")
        src, dst, run = dst, src, 2 * run
    np.testing.assert_array_equal(dst.numpy(), np.sort(host))


def test_launch_count_is_one_chunk_sort_and_the_merges():
    assert [merge_passes(n, 16) for n in (1, 16, 17, 32, 33, 200_000)] == [0, 0, 1, 1, 2, 14]
    assert merge_passes(200_000, 8) == 15
    n = 200_000
    sort = MergeSortKeys(wp.empty(n, dtype=wp.uint64), wp.empty(n, dtype=wp.uint64))
    assert len(sort.steps) == 1 + merge_passes(n)
    assert len(MergeSortKeys(wp.empty(1, dtype=wp.uint64), wp.empty(1, dtype=wp.uint64)).steps) == 0


def test_refuses_what_it_cannot_sort():
    k = wp.empty(10, dtype=wp.uint64)
    with pytest.raises(UtilsError, match="uint64"):
        MergeSortKeys(wp.empty(10, dtype=wp.uint32), wp.empty(10, dtype=wp.uint32))
    with pytest.raises(UtilsError, match="scratch of 10"):
        MergeSortKeys(k, wp.empty(9, dtype=wp.uint64))
    with pytest.raises(UtilsError, match="contiguous 1-d"):
        MergeSortKeys(wp.empty((2, 5), dtype=wp.uint64), wp.empty(10, dtype=wp.uint64))
    with pytest.raises(UtilsError, match="chunk"):
        MergeSortKeys(k, wp.empty(10, dtype=wp.uint64), 0)
    with pytest.raises(UtilsError, match="kdsl array"):
        MergeSortKeys(np.zeros(10, np.uint64), k)


def test_kernels_compile_for_cuda():
    """Compile only: the two kernels through NVRTC (sm_90)."""
    pytest.importorskip("cupy_backends.cuda.libs.nvrtc")
    from kdsl.backends.cuda import BACKEND
    from kdsl.compiler import lower

    for k in (merge_sort._sort_chunks, merge_sort._merge_runs):
        assert ".entry" in lower(BACKEND, k.build_module(), "ptx", {"arch": "sm_90"})
