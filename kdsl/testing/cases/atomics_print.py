"""Conformance cases: atomics on every dtype, and integer semantics edge cases.

Atomics run under contention (many threads on few slots) with results that do not
depend on the order of the updates: integer sums wrap the same way in any order,
float sums add small integers (exact), min/max/and/or/xor are order-free, and
exchange/compare-and-swap are checked through invariants the kernel computes
(every old value seen exactly once). The integer cases pin down kdsl's defined
results for division by zero, ``MIN // -1``, shifts by the bit width or more and
float-to-integer casts of NaN, infinities and out-of-range values (see
``docs/semantics.md``). References are plain Python/NumPy integer arithmetic,
independent of ``kdsl.ir.semantics``. Print output is tested in ``tests/``.
"""

from typing import Any

import numpy as np

import kdsl as wp
from kdsl.testing.case import Case, f64, integers
from kdsl.testing.cases.atomics_composite import SLOTS, N, composite_cases, slots
from kdsl.testing.cases.dtype_rows import FLOAT_TYPES, INT_TYPES
from kdsl.testing.cases.dtype_rows import wrap as _wrap
from kdsl.testing.cases.int_edges import int_cases

# -- add / sub / min / max under contention ------------------------------------------


def _arith_kernel(dtype):
    @wp.kernel
    def atomic_arith(
        v: wp.array(dtype=dtype),
        k: wp.array(dtype=wp.int32),
        total: wp.array(dtype=dtype),
        neg: wp.array(dtype=dtype),
        lo: wp.array(dtype=dtype),
        hi: wp.array(dtype=dtype),
    ):
        i = wp.tid()
        wp.atomic_add(total, k[i], v[i])
        wp.atomic_sub(neg, k[i], v[i])
        wp.atomic_min(lo, k[i], v[i])
        wp.atomic_max(hi, k[i], v[i])

    return atomic_arith


def _arith_inputs(np_dtype):
    def make(rng):
        if np.dtype(np_dtype).kind == "f":
            v = integers(rng, N, -64, 65, np.int64).astype(np_dtype)  # exact sums
            v[:2] = [-0.0, 0.0]
        else:
            info = np.iinfo(np_dtype)
            v = rng.integers(int(info.min), int(info.max), N, dtype=np_dtype, endpoint=True)
            v[:2] = [info.min, info.max]  # wrap-around in the sums
        start = np.zeros(SLOTS, np_dtype)
        if np.dtype(np_dtype).kind == "f":
            lo, hi = np.full(SLOTS, np.inf, np_dtype), np.full(SLOTS, -np.inf, np_dtype)
        else:
            lo, hi = np.full(SLOTS, info.max, np_dtype), np.full(SLOTS, info.min, np_dtype)
        return {"v": v, "k": slots(rng), "total": start, "neg": start.copy(), "lo": lo, "hi": hi}

    return make


def _arith_ref(ins):
    v, k = ins["v"], ins["k"]
    dt = v.dtype
    out: dict[str, Any] = {}
    if dt.kind == "f":
        total = np.zeros(SLOTS)
        np.add.at(total, k, f64(v))
        out["total"], out["neg"] = total, -total
    else:
        sums = [sum(int(x) for x, s in zip(v, k) if s == j) for j in range(SLOTS)]
        out["total"], out["neg"] = _wrap(sums, dt), _wrap([-s for s in sums], dt)
    lo = ins["lo"].astype(np.float64 if dt.kind == "f" else object).copy()
    hi = ins["hi"].astype(np.float64 if dt.kind == "f" else object).copy()
    for x, s in zip(v, k):
        x = float(x) if dt.kind == "f" else int(x)
        lo[s], hi[s] = min(lo[s], x), max(hi[s], x)
    out["lo"] = np.array(lo, dtype=np.float64 if dt.kind == "f" else dt)
    out["hi"] = np.array(hi, dtype=np.float64 if dt.kind == "f" else dt)
    return out


def _arith_cases() -> list[Case]:
    cases = []
    for name, dtype, np_dtype, req in INT_TYPES + FLOAT_TYPES:
        cases.append(Case(f"atomic_add_sub_min_max_{name}", _arith_kernel(dtype), N,
                          _arith_inputs(np_dtype), _arith_ref, ("total", "neg", "lo", "hi"),
                          requires=("atomics", *req)))  # fmt: skip
    return cases


# -- and / or / xor ------------------------------------------------------------------


def _bits_kernel(dtype):
    @wp.kernel
    def atomic_bits(
        v: wp.array(dtype=dtype),
        k: wp.array(dtype=wp.int32),
        a: wp.array(dtype=dtype),
        o: wp.array(dtype=dtype),
        x: wp.array(dtype=dtype),
    ):
        i = wp.tid()
        wp.atomic_and(a, k[i], v[i])
        wp.atomic_or(o, k[i], v[i])
        wp.atomic_xor(x, k[i], v[i])

    return atomic_bits


def _bits_inputs(np_dtype):
    def make(rng):
        info = np.iinfo(np_dtype)
        # Mostly-set words so AND keeps some bits; sparse words so OR does not saturate.
        dense = rng.integers(int(info.min), int(info.max), N, dtype=np_dtype, endpoint=True)
        sparse = np.array([1 << int(b) for b in rng.integers(0, info.bits - 1, N)], np.uint64)
        v = np.where(np.arange(N) % 2 == 0, dense | ~sparse.astype(np_dtype),
                     sparse.astype(np_dtype)).astype(np_dtype)  # fmt: skip
        ones = np.full(SLOTS, -1 if info.min < 0 else info.max, np_dtype)
        return {"v": v, "k": slots(rng), "a": ones, "o": np.zeros(SLOTS, np_dtype),
                "x": np.zeros(SLOTS, np_dtype)}  # fmt: skip

    return make


def _bits_ref(ins):
    v, k = ins["v"], ins["k"]
    a, o, x = ins["a"].copy(), ins["o"].copy(), ins["x"].copy()
    for val, s in zip(v, k):
        a[s] &= val
        o[s] |= val
        x[s] ^= val
    return {"a": a, "o": o, "x": x}


# -- exchange and compare-and-swap ---------------------------------------------------


def _exch_kernel(dtype):
    @wp.kernel
    def atomic_exch_tickets(
        slot: wp.array(dtype=dtype), seen: wp.array(dtype=wp.int32), dup: wp.array(dtype=wp.int32)
    ):
        # Each thread swaps its ticket in; every old value (the initial 0 and all
        # tickets but the last one in) must come out exactly once.
        i = wp.tid()
        old = wp.atomic_exch(slot, 0, dtype(i + 1))
        before = wp.atomic_add(seen, wp.int32(old), 1)
        wp.atomic_max(dup, 0, before)

    return atomic_exch_tickets


def _exch_case(name, dtype, np_dtype, req) -> Case:
    return Case(
        f"atomic_exch_contention_{name}", _exch_kernel(dtype), N,
        lambda rng: {"slot": np.zeros(1, np_dtype), "seen": np.zeros(N + 1, np.int32),
                     "dup": np.zeros(1, np.int32)},
        lambda ins: {"dup": [0]}, ("dup",), requires=("atomics", *req),
    )  # fmt: skip


def _exch_each_kernel(dtype):
    @wp.kernel
    def atomic_exch_each(
        a: wp.array(dtype=dtype), v: wp.array(dtype=dtype), old: wp.array(dtype=dtype)
    ):
        i = wp.tid()
        old[i] = wp.atomic_exch(a, i, v[i])

    return atomic_exch_each


def _cas_counter_kernel(dtype):
    @wp.kernel
    def cas_counter(
        counter: wp.array(dtype=dtype), v: wp.array(dtype=dtype), taken: wp.array(dtype=wp.int32)
    ):
        # A lock-free add built from compare-and-swap: retry until no other thread
        # got in between the read and the swap. Small integer values keep float sums exact.
        i = wp.tid()
        done = False
        while not done:
            cur = counter[0]
            if wp.atomic_cas(counter, 0, cur, cur + v[i]) == cur:
                done = True
        # Tickets: each thread claims a distinct slot with a CAS loop on slot 1.
        got = False
        while not got:
            t = counter[1]
            if wp.atomic_cas(counter, 1, t, t + dtype(1)) == t:
                wp.atomic_add(taken, wp.int32(t), 1)
                got = True

    return cas_counter


def _cas_counter_case(name, dtype, np_dtype, req) -> Case:
    def make(rng):
        return {"counter": np.zeros(2, np_dtype), "v": integers(rng, N, 0, 50).astype(np_dtype),
                "taken": np.zeros(N, np.int32)}  # fmt: skip

    def ref(ins):
        total = sum(int(x) for x in ins["v"])
        return {"counter": np.array([total, N], np.float64), "taken": np.ones(N, np.int32)}

    return Case(f"atomic_cas_counter_{name}", _cas_counter_kernel(dtype), N, make, ref,
                ("counter", "taken"), requires=("atomics", *req))  # fmt: skip


@wp.kernel
def cas_float_bits(
    a: wp.array(dtype=float), cmp: wp.array(dtype=float), new: wp.array(dtype=float),
    old: wp.array(dtype=float), swapped: wp.array(dtype=wp.int32),
):  # fmt: skip
    i = wp.tid()
    o = wp.atomic_cas(a, i, cmp[i], new[i])
    old[i] = o
    swapped[i] = wp.where(a[i] == new[i], 1, 0)


def _cas_bits_inputs(rng):
    nan, inf = np.float32("nan"), np.float32("inf")
    a = np.array([1.5, -0.0, 0.0, nan, inf, 2.0, 1e-45, -3.0], np.float32)
    cmp = np.array([1.5, 0.0, -0.0, nan, inf, 3.0, 1e-45, -3.0], np.float32)
    new = np.array([7.0, 7.0, 7.0, 7.0, 7.0, 7.0, 7.0, 9.0], np.float32)
    return {"a": a, "cmp": cmp, "new": new, "old": np.zeros(8, np.float32),
            "swapped": np.zeros(8, np.int32)}  # fmt: skip


def _cas_bits_ref(ins):
    # Bits decide: -0.0 and +0.0 differ, a NaN matches the same NaN bits.
    same = ins["a"].view(np.uint32) == ins["cmp"].view(np.uint32)
    a = np.where(same, ins["new"], ins["a"])
    return {"a": f64(a), "old": f64(ins["a"]), "swapped": same.astype(np.int32)}


@wp.kernel
def cas_int_each(a: wp.array(dtype=wp.int64), cmp: wp.array(dtype=wp.int64),
                 old: wp.array(dtype=wp.int64)):  # fmt: skip
    i = wp.tid()
    old[i] = wp.atomic_cas(a, i, cmp[i], wp.int64(-i - 1))


def _cas_int_inputs(rng):
    a = integers(rng, 16, -(2**62), 2**62, np.int64)
    cmp = a.copy()
    cmp[1::2] += 1  # odd threads miss
    return {"a": a, "cmp": cmp, "old": np.zeros(16, np.int64)}


def _cas_int_ref(ins):
    a, cmp = ins["a"], ins["cmp"]
    return {"a": np.where(a == cmp, -np.arange(16) - 1, a), "old": a}


def _exch_each_case(name, dtype, np_dtype, req) -> Case:
    def make(rng):
        a = integers(rng, 32, 0, 100).astype(np_dtype)
        return {"a": a, "v": integers(rng, 32, 0, 100).astype(np_dtype),
                "old": np.zeros(32, np_dtype)}  # fmt: skip

    return Case(f"atomic_exch_each_{name}", _exch_each_kernel(dtype), 32, make,
                lambda ins: {"a": ins["v"], "old": ins["a"]}, ("a", "old"),
                requires=("atomics", *req))  # fmt: skip


# -- a fence publishing writes through an atomic counter (bottom-up tree sums) ---------

_LEAVES = 2048


@wp.kernel
def fence_tree_sums(v: wp.array(dtype=wp.int32), sums: wp.array(dtype=wp.int32),
                    arrivals: wp.array(dtype=wp.int32)):  # fmt: skip
    # A heap-ordered binary tree: node 1 is the root, leaf i is node LEAVES + i. The
    # second thread to reach a node sums its children; the first thread's write must be
    # visible to it, which the fence before the counter and the one after guarantee.
    i = wp.tid()
    node = _LEAVES + i
    sums[node] = v[i]
    while node > 1:
        wp.thread_fence()
        parent = node // 2
        if wp.atomic_add(arrivals, parent, 1) == 0:
            break
        wp.thread_fence()
        sums[parent] = sums[2 * parent] + sums[2 * parent + 1]
        node = parent


def _fence_inputs(rng):
    v = integers(rng, _LEAVES, -1000, 1000, np.int32)
    return {"v": v, "sums": np.zeros(2 * _LEAVES, np.int32),
            "arrivals": np.zeros(_LEAVES, np.int32)}  # fmt: skip


def _fence_ref(ins):
    sums = np.zeros(2 * _LEAVES, np.int64)
    sums[_LEAVES:] = ins["v"]
    for node in range(_LEAVES - 1, 0, -1):
        sums[node] = sums[2 * node] + sums[2 * node + 1]
    arrivals = np.full(_LEAVES, 2)
    arrivals[0] = 0
    return {"sums": sums, "arrivals": arrivals}


def _per_type_cases() -> list[Case]:
    cases = _arith_cases()
    cases += [
        Case("atomic_cas_float_bits", cas_float_bits, 8, _cas_bits_inputs, _cas_bits_ref,
             ("a", "old", "swapped"), requires=("atomics",)),
        Case("atomic_cas_i64_each", cas_int_each, 16, _cas_int_inputs, _cas_int_ref,
             ("a", "old"), requires=("atomics", "int64")),
        Case("thread_fence_tree_sums", fence_tree_sums, _LEAVES, _fence_inputs, _fence_ref,
             ("sums", "arrivals"), requires=("atomics",)),
    ]  # fmt: skip
    for name, dtype, np_dtype, req in INT_TYPES:
        cases.append(Case(f"atomic_and_or_xor_{name}", _bits_kernel(dtype), N,
                          _bits_inputs(np_dtype), _bits_ref, ("a", "o", "x"),
                          requires=("atomics", *req)))  # fmt: skip
    for name, dtype, np_dtype, req in INT_TYPES + FLOAT_TYPES:
        cases.append(_exch_case(name, dtype, np_dtype, req))
        cases.append(_exch_each_case(name, dtype, np_dtype, req))
        cases.append(_cas_counter_case(name, dtype, np_dtype, req))
    return cases


CASES: list[Case] = [*_per_type_cases(), *composite_cases(), *int_cases()]
