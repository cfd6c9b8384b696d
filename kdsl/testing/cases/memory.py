"""Thread indices in 1-4 dims, arrays of several ranks and dtypes, atomics, wrap-around."""

import numpy as np

import kdsl as wp
from kdsl.testing.case import Case, f64, integers, uniform


@wp.kernel
def tid_1d(out: wp.array(dtype=wp.int32)):
    i = wp.tid()
    out[i] = i * 3 + 1


@wp.kernel
def tid_2d(out: wp.array2d(dtype=wp.int32)):
    i, j = wp.tid()
    out[i, j] = i * 100 + j


@wp.kernel
def tid_3d(out: wp.array3d(dtype=wp.int32)):
    i, j, k = wp.tid()
    out[i, j, k] = i * 10000 + j * 100 + k


@wp.kernel
def tid_4d(out: wp.array4d(dtype=wp.int32)):
    i, j, k, m = wp.tid()
    out[i, j, k, m] = ((i * 10 + j) * 10 + k) * 10 + m


def _index_grid(shape, weights):
    grids = np.indices(shape)
    return sum(w * g for w, g in zip(weights, grids))


@wp.kernel
def array_shape(a: wp.array2d(dtype=float), out: wp.array(dtype=wp.int32)):
    i = wp.tid()
    out[i] = a.shape[0] * 1000 + a.shape[1] + i


@wp.func
def _row_dot(r: wp.array(dtype=float), w: wp.array(dtype=float)) -> float:
    s = 0.0
    for j in range(r.shape[0]):
        s += r[j] * w[j]
    return s


@wp.kernel
def array_views(a: wp.array2d[float], c: wp.array3d[float], w: wp.array[float],
                out: wp.array2d[float]):  # fmt: skip
    i = wp.tid()
    row = a[i]  # a 1-d view of row i (Warp's a[i] on a 2-d array)
    o = out[i]
    o[0] = _row_dot(row, w)
    o[1] = c[i][1][2] + c[i, 0][row.shape[0] - 1]
    out[i][2] = float(c[i].shape[0] * 10 + c[i].shape[1])
    wp.atomic_add(out[i], 3, row[1])


def _array_views_ref(ins):
    a, c, w = f64(ins["a"]), f64(ins["c"]), f64(ins["w"])
    out = np.zeros((5, 4))
    out[:, 0] = a @ w
    out[:, 1] = c[:, 1, 2] + c[:, 0, a.shape[1] - 1]
    out[:, 2] = c.shape[1] * 10 + c.shape[2]
    out[:, 3] = a[:, 1]
    return {"out": out}


@wp.kernel
def atomic_add_contention(
    a: wp.array(dtype=float),
    k: wp.array(dtype=wp.int32),
    total: wp.array(dtype=float),
    counts: wp.array(dtype=wp.int32),
):
    i = wp.tid()
    wp.atomic_add(total, 0, a[i])
    wp.atomic_add(counts, k[i], 1)


def _atomic_add_inputs(rng):
    n = 200
    # Small integers are exact in f32, so the sum does not depend on the order.
    return {
        "a": integers(rng, n, -8, 9).astype(np.float32),
        "k": integers(rng, n, 0, 4),
        "total": np.zeros(1, np.float32),
        "counts": np.zeros(4, np.int32),
    }


def _atomic_add_ref(ins):
    return {
        "total": np.array([ins["a"].astype(np.float64).sum()]),
        "counts": np.bincount(ins["k"], minlength=4),
    }


@wp.kernel
def atomic_min_max(
    a: wp.array(dtype=float),
    k: wp.array(dtype=wp.int32),
    lo: wp.array(dtype=float),
    hi: wp.array(dtype=float),
    ilo: wp.array(dtype=wp.int32),
    ihi: wp.array(dtype=wp.int32),
):
    i = wp.tid()
    wp.atomic_min(lo, 0, a[i])
    wp.atomic_max(hi, 0, a[i])
    wp.atomic_min(ilo, 0, k[i])
    wp.atomic_max(ihi, 0, k[i])


def _atomic_minmax_inputs(rng):
    n = 200
    return {
        "a": uniform(rng, n, -100, 100),
        "k": integers(rng, n, -1000, 1000),
        "lo": np.full(1, 1e9, np.float32),
        "hi": np.full(1, -1e9, np.float32),
        "ilo": np.full(1, 2**30, np.int32),
        "ihi": np.full(1, -(2**30), np.int32),
    }


def _atomic_minmax_ref(ins):
    return {
        "lo": [f64(ins["a"]).min()],
        "hi": [f64(ins["a"]).max()],
        "ilo": [ins["k"].min()],
        "ihi": [ins["k"].max()],
    }


@wp.kernel
def atomic_return_old(counter: wp.array(dtype=wp.int32), slots: wp.array(dtype=wp.int32)):
    # Each thread claims a unique slot; the old values must be a permutation.
    old = wp.atomic_add(counter, 0, 1)
    slots[old] = 1


@wp.kernel
def float16_arith(
    a: wp.array(dtype=wp.float16),
    b: wp.array(dtype=wp.float16),
    out: wp.array(dtype=wp.float16),
    widened: wp.array(dtype=float),
):
    i = wp.tid()
    out[i] = a[i] * b[i] + a[i]
    widened[i] = float(a[i]) * 2.0


@wp.kernel
def int64_wrap(
    a: wp.array(dtype=wp.int64),
    b: wp.array(dtype=wp.int64),
    s: wp.array(dtype=wp.int64),
    p: wp.array(dtype=wp.int64),
):
    i = wp.tid()
    s[i] = a[i] + b[i]
    p[i] = a[i] * b[i]


def _wrap64(x: list[int]) -> np.ndarray:
    return np.array([(v + 2**63) % 2**64 - 2**63 for v in x], np.int64)


def _int64_ref(ins):
    a, b = [int(v) for v in ins["a"]], [int(v) for v in ins["b"]]
    return {
        "s": _wrap64([x + y for x, y in zip(a, b)]),
        "p": _wrap64([x * y for x, y in zip(a, b)]),
    }


@wp.kernel
def uint32_wrap(
    a: wp.array(dtype=wp.uint32),
    b: wp.array(dtype=wp.uint32),
    s: wp.array(dtype=wp.uint32),
    d: wp.array(dtype=wp.uint32),
    p: wp.array(dtype=wp.uint32),
):
    i = wp.tid()
    s[i] = a[i] + b[i]
    d[i] = a[i] - b[i]
    p[i] = a[i] * b[i]


def _uint32_ref(ins):
    a, b = [int(v) for v in ins["a"]], [int(v) for v in ins["b"]]
    m = 2**32
    return {
        "s": np.array([(x + y) % m for x, y in zip(a, b)], np.uint64),
        "d": np.array([(x - y) % m for x, y in zip(a, b)], np.uint64),
        "p": np.array([(x * y) % m for x, y in zip(a, b)], np.uint64),
    }


@wp.kernel
def vec3_array_rw(a: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    n = a.shape[0]
    out[i] = a[n - 1 - i] + a[i] * 0.5


def _zeros(shape, dtype=np.float32):
    return np.zeros(shape, dtype)


CASES = [
    Case("tid_1d", tid_1d, 37, lambda rng: {"out": _zeros(37, np.int32)},
         lambda ins: {"out": np.arange(37) * 3 + 1}, ("out",)),
    Case("tid_2d", tid_2d, (5, 7), lambda rng: {"out": _zeros((5, 7), np.int32)},
         lambda ins: {"out": _index_grid((5, 7), (100, 1))}, ("out",)),
    Case("tid_3d", tid_3d, (3, 4, 5), lambda rng: {"out": _zeros((3, 4, 5), np.int32)},
         lambda ins: {"out": _index_grid((3, 4, 5), (10000, 100, 1))}, ("out",)),
    Case("tid_4d", tid_4d, (2, 3, 2, 4), lambda rng: {"out": _zeros((2, 3, 2, 4), np.int32)},
         lambda ins: {"out": _index_grid((2, 3, 2, 4), (1000, 100, 10, 1))}, ("out",)),
    Case("array_shape", array_shape, 6,
         lambda rng: {"a": _zeros((7, 3)), "out": _zeros(6, np.int32)},
         lambda ins: {"out": 7000 + 3 + np.arange(6)}, ("out",)),
    Case("array_views", array_views, 5,
         lambda rng: {"a": uniform(rng, (5, 3), -2, 2), "c": uniform(rng, (5, 2, 4), -2, 2),
                      "w": uniform(rng, 3, -1, 1), "out": _zeros((5, 4))},
         _array_views_ref, ("out",), requires=("atomics",)),
    Case("atomic_add_contention", atomic_add_contention, 200, _atomic_add_inputs,
         _atomic_add_ref, ("total", "counts"), requires=("atomics",)),
    Case("atomic_min_max_contention", atomic_min_max, 200, _atomic_minmax_inputs,
         _atomic_minmax_ref, ("lo", "hi", "ilo", "ihi"), requires=("atomics",)),
    Case("atomic_add_returns_old", atomic_return_old, 64,
         lambda rng: {"counter": _zeros(1, np.int32), "slots": _zeros(64, np.int32)},
         lambda ins: {"counter": [64], "slots": np.ones(64)}, ("counter", "slots"),
         requires=("atomics",)),
    Case("float16_arrays", float16_arith, 48,
         lambda rng: {"a": uniform(rng, 48, -4, 4, np.float16), "b": uniform(rng, 48, -2, 2, np.float16),
                      "out": _zeros(48, np.float16), "widened": _zeros(48)},
         lambda ins: {"out": f64(ins["a"]) * f64(ins["b"]) + f64(ins["a"]),
                      "widened": 2 * f64(ins["a"])}, ("out", "widened"), requires=("fp16",)),
    Case("int64_wraparound", int64_wrap, 16,
         lambda rng: {"a": integers(rng, 16, -(2**62), 2**62, np.int64) * 3,
                      "b": integers(rng, 16, -(2**62), 2**62, np.int64),
                      "s": _zeros(16, np.int64), "p": _zeros(16, np.int64)},
         _int64_ref, ("s", "p"), requires=("int64",)),
    Case("uint32_wraparound", uint32_wrap, 32,
         lambda rng: {"a": integers(rng, 32, 0, 2**32, np.uint32),
                      "b": integers(rng, 32, 0, 2**32, np.uint32), "s": _zeros(32, np.uint32),
                      "d": _zeros(32, np.uint32), "p": _zeros(32, np.uint32)},
         _uint32_ref, ("s", "d", "p")),
    Case("vec3_arrays", vec3_array_rw, 20,
         lambda rng: {"a": uniform(rng, (20, 3), -5, 5), "out": _zeros((20, 3))},
         lambda ins: {"out": f64(ins["a"])[::-1] + 0.5 * f64(ins["a"])}, ("out",)),
]  # fmt: skip


# --- thread-local arrays (``zeros`` in a kernel) -------------------------------------------


@wp.kernel
def local_arrays(a: wp.array2d(dtype=float), out: wp.array2d(dtype=float)):
    # A stack (push every positive value, pop them back in reverse), a 2-d local array of
    # vectors indexed at run time, and a histogram updated atomically.
    i = wp.tid()
    stack = wp.zeros(8, dtype=float)
    grid = wp.zeros((2, 4), dtype=wp.vec2)
    hist = wp.zeros(shape=3, dtype=int)
    top = 0
    for j in range(8):
        x = a[i, j]
        if x > 0.0:
            stack[top] = x
            top += 1
        grid[j % 2, j // 2] = wp.vec2(x, float(j))
        wp.atomic_add(hist, wp.clamp(int((x + 1.0) * 1.5), 0, 2), 1)
    r = 0.0
    k = 1.0
    while top > 0:
        top -= 1
        r += stack[top] * k
        k += 1.0
    out[i, 0] = r
    out[i, 1] = grid[1, 3][0] - grid[0, 1][0] + grid[1, 2][1]
    out[i, 2] = float(hist[0] * 100 + hist[1] * 10 + hist[2])


def _local_arrays_ref(ins):
    a = f64(ins["a"]).astype(np.float32)
    out = np.zeros((len(a), 3))
    for i, row in enumerate(a):
        pos = [float(x) for x in row if x > 0][::-1]
        out[i, 0] = sum(x * (k + 1) for k, x in enumerate(pos))
        out[i, 1] = float(row[7]) - float(row[2]) + 5.0
        bins = np.clip(((row + np.float32(1.0)) * np.float32(1.5)).astype(np.int32), 0, 2)
        h = np.bincount(bins, minlength=3)
        out[i, 2] = h[0] * 100 + h[1] * 10 + h[2]
    return {"out": out}


CASES.append(
    Case("local_arrays", local_arrays, 24,
         lambda rng: {"a": uniform(rng, (24, 8), -1, 1), "out": _zeros((24, 3))},
         _local_arrays_ref, ("out",), requires=("atomics",))
)  # fmt: skip
