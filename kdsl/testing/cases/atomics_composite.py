"""Atomic conformance cases on composite and uncommon types (helper of ``atomics_print``).

Vectors and matrices (componentwise atomics), float16 sums, 8- and 16-bit integers,
bools, 2-d and 3-d indices, NaN/infinity/signed-zero edges of float min/max, and
``arr[i] += x`` (an atomic add, as in Warp). Results do not depend on the order in
which threads arrive.
"""

import numpy as np

import kdsl as wp
from kdsl.testing.case import Case, f64, integers
from kdsl.testing.cases.dtype_rows import SMALL_INT_TYPES
from kdsl.testing.cases.dtype_rows import wrap as _wrap

N = 256  # threads of the contention cases
SLOTS = 5


def slots(rng: np.random.Generator) -> np.ndarray:
    """A slot in ``[0, SLOTS)`` per thread."""
    return integers(rng, N, 0, SLOTS)


def _vec_kernel(vtype):
    """Componentwise add, min, max and sub of ``vtype`` vectors into contended slots."""

    @wp.kernel
    def atomic_vec(
        v: wp.array(dtype=vtype), k: wp.array(dtype=wp.int32), total: wp.array(dtype=vtype),
        lo: wp.array(dtype=vtype), hi: wp.array(dtype=vtype), neg: wp.array(dtype=vtype),
    ):  # fmt: skip
        i = wp.tid()
        wp.atomic_add(total, k[i], v[i])
        wp.atomic_min(lo, k[i], v[i])
        wp.atomic_max(hi, k[i], v[i])
        wp.atomic_sub(neg, k[i], v[i])

    return atomic_vec


def _vec_inputs(np_dtype, length):
    def make(rng):
        v = integers(rng, (N, length), -40, 41).astype(np_dtype)
        return {"v": v, "k": slots(rng), "total": np.zeros((SLOTS, length), np_dtype),
                "lo": np.full((SLOTS, length), 1e9, np_dtype),
                "hi": np.full((SLOTS, length), -1e9, np_dtype),
                "neg": np.zeros((SLOTS, length), np_dtype)}  # fmt: skip

    return make


def _vec_ref(ins):
    v, k = f64(ins["v"]), ins["k"]
    total = np.zeros(ins["total"].shape)
    np.add.at(total, k, v)
    lo, hi = f64(ins["lo"]).copy(), f64(ins["hi"]).copy()
    np.minimum.at(lo, k, v)
    np.maximum.at(hi, k, v)
    return {"total": total, "lo": lo, "hi": hi, "neg": -total}


@wp.kernel
def atomic_mat22(v: wp.array(dtype=wp.mat22), total: wp.array(dtype=wp.mat22),
                 old: wp.array(dtype=wp.mat22)):  # fmt: skip
    i = wp.tid()
    wp.atomic_add(total, i % 2, v[i])
    old[i] = wp.atomic_exch(old, i, v[i] * 2.0)


def _mat_inputs(rng):
    return {
        "v": integers(rng, (64, 2, 2), -9, 10).astype(np.float32),
        "total": np.zeros((2, 2, 2), np.float32),
        "old": np.ones((64, 2, 2), np.float32),
    }


def _mat_ref(ins):
    v = f64(ins["v"])
    return {"total": np.stack([v[0::2].sum(0), v[1::2].sum(0)]), "old": np.ones((64, 2, 2))}


@wp.kernel
def atomic_vec_cas(a: wp.array(dtype=wp.vec3i), cmp: wp.array(dtype=wp.vec3i),
                   new: wp.array(dtype=wp.vec3i), old: wp.array(dtype=wp.vec3i)):  # fmt: skip
    i = wp.tid()
    old[i] = wp.atomic_cas(a, i, cmp[i], new[i])


def _vec_cas_inputs(rng):
    a = integers(rng, (12, 3), -100, 100)
    cmp = np.where(rng.random((12, 3)) < 0.5, a, a + 1).astype(np.int32)
    return {"a": a, "cmp": cmp, "new": integers(rng, (12, 3), -100, 100),
            "old": np.zeros((12, 3), np.int32)}  # fmt: skip


def _vec_cas_ref(ins):
    a, cmp, new = ins["a"], ins["cmp"], ins["new"]
    return {"a": np.where(a == cmp, new, a), "old": a}


@wp.kernel
def atomic_add_f16(v: wp.array(dtype=wp.float16), k: wp.array(dtype=wp.int32),
                   total: wp.array(dtype=wp.float16), neg: wp.array(dtype=wp.float16)):  # fmt: skip
    i = wp.tid()
    wp.atomic_add(total, k[i], v[i])
    wp.atomic_sub(neg, k[i], v[i])


def _f16_inputs(rng):
    # |partial sums| stay below 2048, where every integer is exact in float16.
    return {
        "v": integers(rng, N, -6, 7).astype(np.float16),
        "k": slots(rng),
        "total": np.zeros(SLOTS, np.float16),
        "neg": np.zeros(SLOTS, np.float16),
    }


def _f16_ref(ins):
    total = np.zeros(SLOTS)
    np.add.at(total, ins["k"], f64(ins["v"]))
    return {"total": total, "neg": -total}


def _small_kernel(dtype):
    @wp.kernel
    def atomic_small_int(v: wp.array(dtype=dtype), k: wp.array(dtype=wp.int32),
                         total: wp.array(dtype=dtype), lo: wp.array(dtype=dtype),
                         hi: wp.array(dtype=dtype), x: wp.array(dtype=dtype)):  # fmt: skip
        i = wp.tid()
        wp.atomic_add(total, k[i], v[i])
        wp.atomic_min(lo, k[i], v[i])
        wp.atomic_max(hi, k[i], v[i])
        wp.atomic_xor(x, k[i], v[i])

    return atomic_small_int


def _small_inputs(np_dtype):
    def make(rng):
        info = np.iinfo(np_dtype)
        v = rng.integers(int(info.min), int(info.max), N, dtype=np_dtype, endpoint=True)
        return {"v": v, "k": slots(rng), "total": np.zeros(SLOTS, np_dtype),
                "lo": np.full(SLOTS, info.max, np_dtype), "hi": np.full(SLOTS, info.min, np_dtype),
                "x": np.zeros(SLOTS, np_dtype)}  # fmt: skip

    return make


def _small_ref(ins):
    v, k = ins["v"], ins["k"]
    dt = v.dtype
    sums = [sum(int(x) for x, s in zip(v, k) if s == j) for j in range(SLOTS)]
    lo, hi, x = ins["lo"].copy(), ins["hi"].copy(), ins["x"].copy()
    for val, s in zip(v, k):
        lo[s], hi[s] = min(lo[s], val), max(hi[s], val)
        x[s] ^= val
    return {"total": _wrap(sums, dt), "lo": lo, "hi": hi, "x": x}


@wp.kernel
def atomic_bool_exch(v: wp.array(dtype=wp.int32), flags: wp.array(dtype=wp.bool),
                   old: wp.array(dtype=wp.bool)):  # fmt: skip
    i = wp.tid()
    old[i] = wp.atomic_exch(flags, v[i], True)


@wp.kernel
def atomic_2d_3d(k: wp.array(dtype=wp.int32), grid: wp.array2d(dtype=wp.int32),
                 cube: wp.array3d(dtype=float)):  # fmt: skip
    i = wp.tid()
    wp.atomic_add(grid, k[i] % 3, k[i] // 3, 1)
    wp.atomic_max(cube, k[i] % 2, 1, k[i] % 4, float(i))


def _nd_inputs(rng):
    return {
        "k": integers(rng, N, 0, 12),
        "grid": np.zeros((3, 4), np.int32),
        "cube": np.full((2, 2, 4), -1.0, np.float32),
    }


def _nd_ref(ins):
    k = ins["k"]
    grid = np.zeros((3, 4), np.int64)
    np.add.at(grid, (k % 3, k // 3), 1)
    cube = np.full((2, 2, 4), -1.0)
    for i, kk in enumerate(k):
        cube[kk % 2, 1, kk % 4] = max(cube[kk % 2, 1, kk % 4], i)
    return {"grid": grid, "cube": cube}


@wp.kernel
def atomic_minmax_float_edges(v: wp.array(dtype=float), lo: wp.array(dtype=float),
                              hi: wp.array(dtype=float)):  # fmt: skip
    i = wp.tid()
    wp.atomic_min(lo, i % 2, v[i])
    wp.atomic_max(hi, i % 2, v[i])


def _edge_inputs(rng):
    # Slot 0 sees NaN and both zeros, slot 1 infinities and subnormals.
    v = np.array([np.nan, -0.0, 0.0, np.inf, np.nan, -np.inf, 0.0, 1e-45, -0.0, -1e-45],
                 np.float32)  # fmt: skip
    return {"v": v, "lo": np.full(2, np.nan, np.float32), "hi": np.full(2, np.nan, np.float32)}


def _edge_ref(ins):
    # NaN loses to any number (the sign of the zeros is checked by atomic_zero_sign).
    return {"lo": [-0.0, -np.inf], "hi": [0.0, np.inf]}


@wp.kernel
def atomic_zero_sign(v: wp.array(dtype=float), a: wp.array(dtype=float),
                     inv: wp.array(dtype=float)):  # fmt: skip
    # One thread, so the order is known: min(+0, -0) is -0, max(-0, +0) is +0, a NaN
    # value loses to the number in memory and a number replaces a NaN there.
    wp.atomic_min(a, 0, v[0])
    wp.atomic_max(a, 1, v[1])
    wp.atomic_min(a, 2, v[2])
    wp.atomic_max(a, 3, v[3])
    inv[0] = 1.0 / a[0]
    inv[1] = 1.0 / a[1]


def _zero_sign_inputs(rng):
    return {
        "v": np.array([-0.0, 0.0, np.nan, 2.0], np.float32),
        "a": np.array([0.0, -0.0, 1.0, np.nan], np.float32),
        "inv": np.zeros(2, np.float32),
    }


@wp.kernel
def augassign_atomic(k: wp.array(dtype=wp.int32), v: wp.array(dtype=float),
                     total: wp.array(dtype=float), grid: wp.array2d(dtype=wp.vec2),
                     scaled: wp.array(dtype=float)):  # fmt: skip
    # As in Warp, += and -= on an array element are atomic adds/subs; *= is not atomic
    # (each thread scales its own element here).
    i = wp.tid()
    total[k[i]] += v[i]
    total[SLOTS] -= 1.0
    grid[k[i] % 2, 1] += wp.vec2(v[i], 1.0)
    scaled[i] *= 3.0


def _augassign_inputs(rng):
    return {"k": slots(rng), "v": integers(rng, N, -20, 21).astype(np.float32),
            "total": np.zeros(SLOTS + 1, np.float32), "grid": np.zeros((2, 2, 2), np.float32),
            "scaled": integers(rng, N, -5, 6).astype(np.float32)}  # fmt: skip


def _augassign_ref(ins):
    k, v = ins["k"], f64(ins["v"])
    total = np.zeros(SLOTS + 1)
    np.add.at(total, k, v)
    total[SLOTS] = -N
    grid = np.zeros((2, 2, 2))
    np.add.at(grid[:, 1, 0], k % 2, v)
    np.add.at(grid[:, 1, 1], k % 2, 1.0)
    return {"total": total, "grid": grid, "scaled": 3 * f64(ins["scaled"])}


def composite_cases() -> list[Case]:
    """Vectors, matrices, float16, small integers, bools, n-d indices, edge values, +=."""
    cases = [
        Case("atomic_vec3f_contention", _vec_kernel(wp.vec3), N, _vec_inputs(np.float32, 3),
             _vec_ref, ("total", "lo", "hi", "neg"), requires=("atomics",)),
        Case("atomic_vec2d_contention", _vec_kernel(wp.vec2d), N, _vec_inputs(np.float64, 2),
             _vec_ref, ("total", "lo", "hi", "neg"), requires=("atomics", "fp64")),
        Case("atomic_vec4i_contention", _vec_kernel(wp.vec4i), N, _vec_inputs(np.int32, 4),
             lambda ins: {k: v.astype(np.int64) for k, v in _vec_ref(ins).items()},
             ("total", "lo", "hi", "neg"), requires=("atomics",)),
        Case("atomic_mat22_add_exch", atomic_mat22, 64, _mat_inputs, _mat_ref,
             ("total", "old"), requires=("atomics",)),
        Case("atomic_cas_vec3i", atomic_vec_cas, 12, _vec_cas_inputs, _vec_cas_ref,
             ("a", "old"), requires=("atomics",)),
        Case("atomic_add_sub_f16", atomic_add_f16, N, _f16_inputs, _f16_ref, ("total", "neg"),
             requires=("atomics", "fp16")),
        Case("atomic_exch_bool", atomic_bool_exch, 64,
             lambda rng: {"v": np.arange(64, dtype=np.int32) % 4,
                          "flags": np.zeros(4, bool), "old": np.ones(64, bool)},
             lambda ins: {"flags": np.ones(4, bool)}, ("flags",), requires=("atomics",)),
        Case("atomic_2d_3d_indices", atomic_2d_3d, N, _nd_inputs, _nd_ref, ("grid", "cube"),
             requires=("atomics",)),
        Case("atomic_min_max_nan_inf_zero", atomic_minmax_float_edges, 10, _edge_inputs,
             _edge_ref, ("lo", "hi"), requires=("atomics",)),
        Case("array_augassign_is_atomic", augassign_atomic, N, _augassign_inputs, _augassign_ref,
             ("total", "grid", "scaled"), requires=("atomics",)),
        Case("atomic_min_max_signed_zero", atomic_zero_sign, 1, _zero_sign_inputs,
             lambda ins: {"a": [-0.0, 0.0, 1.0, 2.0], "inv": [-np.inf, np.inf]}, ("a", "inv"),
             requires=("atomics",)),
    ]  # fmt: skip
    for name, dtype, np_dtype, req in SMALL_INT_TYPES:
        cases.append(Case(f"atomic_small_int_{name}", _small_kernel(dtype), N,
                          _small_inputs(np_dtype), _small_ref, ("total", "lo", "hi", "x"),
                          requires=("atomics", *req)))  # fmt: skip
    return cases
