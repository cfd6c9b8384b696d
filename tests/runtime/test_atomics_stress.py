"""Atomics under real contention on cpu (every launch on the pool) and cuda (if present).

The conformance cases check atomic semantics with small launches (which the cpu
backend may run on one thread); here 4 pool threads, or a whole GPU, hammer a few
slots, so a non-atomic lowering (a load and a store) would lose updates and fail.
"""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.backends.cpu import pool

N = 1 << 17
SLOTS = 3


DEVICES = ["cpu", pytest.param("cuda:0", marks=pytest.mark.skipif(
    not wp.is_cuda_available(), reason="needs a CUDA GPU"))]  # fmt: skip


@pytest.fixture(autouse=True)
def _on_the_pool():
    old = pool.num_threads(), pool.min_parallel, pool.adaptive
    pool.set_num_threads(4)
    pool.min_parallel, pool.adaptive = 1, False
    try:
        yield
    finally:
        pool.set_num_threads(old[0])
        pool.min_parallel, pool.adaptive = old[1], old[2]


@wp.kernel
def hammer(
    ci: wp.array(dtype=wp.int32), cf: wp.array(dtype=float), cd: wp.array(dtype=wp.float64),
    ch: wp.array(dtype=wp.float16), cb: wp.array(dtype=wp.int8), cl: wp.array(dtype=wp.uint64),
    bits: wp.array(dtype=wp.uint32), lo: wp.array(dtype=wp.float64), hi: wp.array(dtype=wp.int64),
    v: wp.array(dtype=wp.vec3),
):  # fmt: skip
    i = wp.tid()
    s = i % 3
    wp.atomic_add(ci, s, 1)
    wp.atomic_sub(cf, s, 1.0)
    wp.atomic_add(cd, s, 0.5)
    wp.atomic_add(ch, i % 128, wp.float16(1.0))
    wp.atomic_add(cb, s, wp.int8(3))
    wp.atomic_add(cl, s, wp.uint64(0xFFFFFFFFFFFF))
    wp.atomic_or(bits, 0, wp.uint32(1) << wp.uint32(i % 32))
    wp.atomic_xor(bits, 1, wp.uint32(i))
    wp.atomic_and(bits, 2, ~(wp.uint32(1) << wp.uint32(i % 31)))
    wp.atomic_min(lo, s, wp.float64(i) * -0.25)
    wp.atomic_max(hi, s, wp.int64(i) * wp.int64(1000000007))
    wp.atomic_add(v, s, wp.vec3(1.0, -2.0, 0.25))
    ci[s] += 2  # augmented assignment to an element is atomic, as in Warp
    cd[s] -= 0.25


@pytest.mark.parametrize("device", DEVICES)
def test_every_atomic_kind_is_atomic_under_contention(device):
    z = {
        "ci": wp.zeros(SLOTS, dtype=wp.int32), "cf": wp.zeros(SLOTS, dtype=float),
        "cd": wp.zeros(SLOTS, dtype=wp.float64), "ch": wp.zeros(128, dtype=wp.float16),
        "cb": wp.zeros(SLOTS, dtype=wp.int8), "cl": wp.zeros(SLOTS, dtype=wp.uint64),
        "bits": wp.array(np.array([0, 0, 0xFFFFFFFF], np.uint32)),
        "lo": wp.zeros(SLOTS, dtype=wp.float64), "hi": wp.zeros(SLOTS, dtype=wp.int64),
        "v": wp.zeros(SLOTS, dtype=wp.vec3),
    }  # fmt: skip
    z = {k: v.to(device) for k, v in z.items()}
    wp.launch(hammer, N, list(z.values()), device=device)
    per = np.bincount(np.arange(N) % 3)
    np.testing.assert_array_equal(z["ci"].numpy(), per * 3)
    np.testing.assert_array_equal(z["cf"].numpy(), -per)
    np.testing.assert_array_equal(z["cd"].numpy(), per * 0.25)
    np.testing.assert_array_equal(z["ch"].numpy(), np.full(128, N // 128))
    np.testing.assert_array_equal(z["cb"].numpy(), (per * 3).astype(np.uint8).view(np.int8))
    want_l = [(int(p) * 0xFFFFFFFFFFFF) % 2**64 for p in per]
    np.testing.assert_array_equal(z["cl"].numpy(), np.array(want_l, np.uint64))
    xor = np.bitwise_xor.reduce(np.arange(N, dtype=np.uint32))
    np.testing.assert_array_equal(z["bits"].numpy(), [0xFFFFFFFF, xor, 0x80000000])
    last = [max(i for i in range(N - 3, N) if i % 3 == s) for s in range(3)]
    np.testing.assert_array_equal(z["lo"].numpy(), [x * -0.25 for x in last])
    np.testing.assert_array_equal(z["hi"].numpy(), [x * 1000000007 for x in last])
    np.testing.assert_array_equal(z["v"].numpy(), per[:, None] * np.array([1.0, -2.0, 0.25]))


@wp.kernel
def tickets(slot: wp.array(dtype=wp.int32), seen: wp.array(dtype=wp.int32),
            counter: wp.array(dtype=float), taken: wp.array(dtype=wp.int32)):  # fmt: skip
    i = wp.tid()
    old = wp.atomic_exch(slot, 0, i + 1)
    wp.atomic_add(seen, old, 1)
    done = False
    while not done:  # a lock-free float add from compare-and-swap
        cur = counter[0]
        if wp.atomic_cas(counter, 0, cur, cur + 1.0) == cur:
            wp.atomic_add(taken, wp.int32(cur), 1)
            done = True


@pytest.mark.parametrize("device", DEVICES)
def test_exchange_and_compare_and_swap_hand_out_each_value_once(device):
    n = 1 << 15
    slot, seen = (
        wp.zeros(1, dtype=wp.int32, device=device),
        wp.zeros(n + 1, dtype=wp.int32, device=device),
    )
    counter, taken = (
        wp.zeros(1, dtype=float, device=device),
        wp.zeros(n, dtype=wp.int32, device=device),
    )
    wp.launch(tickets, n, [slot, seen, counter, taken], device=device)
    s = seen.numpy()
    final = int(slot.numpy()[0])
    assert s.max() == 1 and s.sum() == n and s[final] == 0  # every old value once
    assert counter.numpy()[0] == n
    np.testing.assert_array_equal(taken.numpy(), np.ones(n))
