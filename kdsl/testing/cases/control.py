# ruff: noqa: UP018, RUF046 - kernels keep Warp's idiom float(0.0) for a mutable local
"""Control flow: if/elif/else, ternaries, loops of every kind, break/continue/return."""

import numpy as np

import kdsl as wp
from kdsl.testing.case import Case, f64, integers, uniform

N = 32


@wp.kernel
def if_elif_else(a: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    x = a[i]
    y = float(0.0)
    if x < -1.0:
        y = -x * 2.0
    elif x < 0.0:
        y = x + 10.0
    elif x == 0.0:
        y = 100.0
    else:
        y = wp.sqrt(x)
    out[i] = y


def _if_ref(ins):
    x = f64(ins["a"])
    safe = np.where(x > 0, x, 0)
    y = np.select([x < -1, x < 0, x == 0], [-2 * x, x + 10, np.full_like(x, 100.0)], np.sqrt(safe))
    return {"out": y}


@wp.kernel
def ternary(a: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    x = a[i]
    out[i] = x * 3.0 if x > 0.5 else (x - 1.0 if x < -0.5 else 0.0)


@wp.kernel
def for_runtime(n: wp.array(dtype=wp.int32), out: wp.array(dtype=float)):
    i = wp.tid()
    s = float(0.0)
    p = float(1.0)
    for k in range(n[i]):
        s += float(k) * p
        p = p * 0.5
    out[i] = s


def _for_ref(ins):
    out = []
    for n in ins["n"]:
        k = np.arange(n)
        out.append(np.sum(k * 0.5**k))
    return {"out": np.array(out)}


@wp.kernel
def for_negative_step(n: wp.array(dtype=wp.int32), out: wp.array(dtype=wp.int32)):
    i = wp.tid()
    s = int(0)
    for k in range(n[i], -3, -2):
        s = s * 3 + k
    out[i] = s


def _neg_step_ref(ins):
    out = []
    for n in ins["n"]:
        s = 0
        for k in range(int(n), -3, -2):
            s = s * 3 + k
        out.append(s)
    return {"out": np.array(out)}


@wp.kernel
def nested_loops(n: wp.array(dtype=wp.int32), out: wp.array(dtype=wp.int32)):
    i = wp.tid()
    s = int(0)
    for a in range(n[i]):
        for b in range(a, n[i]):
            s += a * b + 1
    out[i] = s


def _nested_ref(ins):
    return {"out": np.array([sum(a * b + 1 for a in range(n) for b in range(a, n))
                             for n in ins["n"]])}  # fmt: skip


@wp.kernel
def while_collatz(a: wp.array(dtype=wp.int32), steps: wp.array(dtype=wp.int32)):
    i = wp.tid()
    x = a[i]
    count = int(0)
    while x != 1:
        if x % 2 == 0:
            x = x // 2
        else:
            x = 3 * x + 1
        count += 1
    steps[i] = count


def _collatz_ref(ins):
    out = []
    for x in ins["a"]:
        x, c = int(x), 0
        while x != 1:
            x = x // 2 if x % 2 == 0 else 3 * x + 1
            c += 1
        out.append(c)
    return {"steps": np.array(out)}


@wp.kernel
def loop_break(a: wp.array2d(dtype=float), first: wp.array(dtype=wp.int32)):
    # Index of the first value above 0.8 in each row, or -1.
    i = wp.tid()
    found = int(-1)
    for k in range(a.shape[1]):
        if a[i, k] > 0.8:
            found = k
            break
    first[i] = found


def _break_ref(ins):
    a = ins["a"]
    hit = a > 0.8
    return {"first": np.where(hit.any(1), hit.argmax(1), -1)}


@wp.kernel
def loop_continue(a: wp.array2d(dtype=float), out: wp.array(dtype=float)):
    # Sum of the non-negative entries, skipping odd columns.
    i = wp.tid()
    s = float(0.0)
    for k in range(a.shape[1]):
        if k % 2 == 1:
            continue
        if a[i, k] < 0.0:
            continue
        s += a[i, k]
    out[i] = s


def _continue_ref(ins):
    a = f64(ins["a"])[:, ::2]
    return {"out": np.where(a < 0, 0, a).sum(1)}


@wp.kernel
def while_break_continue(a: wp.array(dtype=wp.int32), out: wp.array(dtype=wp.int32)):
    i = wp.tid()
    k = int(0)
    s = int(0)
    while True:
        k += 1
        if k > a[i]:
            break
        if k % 3 == 0:
            continue
        s += k
    out[i] = s


def _wbc_ref(ins):
    return {"out": np.array([sum(k for k in range(1, n + 1) if k % 3) for n in ins["a"]])}


@wp.kernel
def early_return(a: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = -1.0
    if a[i] < 0.0:
        return
    for k in range(4):
        if float(k) > a[i]:
            out[i] = float(k)
            return
    out[i] = 99.0


def _early_ref(ins):
    a = f64(ins["a"])
    out = np.where(a < 0, -1.0, 99.0)
    for idx, x in enumerate(a):
        if x >= 0:
            for k in range(4):
                if k > x:
                    out[idx] = k
                    break
    return {"out": out}


@wp.kernel
def static_unroll(a: wp.array2d(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    s = float(0.0)
    for k in range(wp.static(4)):
        s += a[i, k] * float(k + 1)
    out[i] = s


CASES = [
    Case("if_elif_else", if_elif_else, N,
         lambda rng: {"a": np.concatenate([uniform(rng, N - 2, -3, 3), [0.0, -1.0]]).astype(np.float32),
                      "out": np.zeros(N, np.float32)}, _if_ref, ("out",)),
    Case("ternary", ternary, N,
         lambda rng: {"a": uniform(rng, N, -2, 2), "out": np.zeros(N, np.float32)},
         lambda ins: {"out": np.where(f64(ins["a"]) > 0.5, 3 * f64(ins["a"]),
                                      np.where(f64(ins["a"]) < -0.5, f64(ins["a"]) - 1, 0.0))},
         ("out",)),
    Case("for_runtime_carried", for_runtime, N,
         lambda rng: {"n": integers(rng, N, 0, 20), "out": np.zeros(N, np.float32)},
         _for_ref, ("out",)),
    Case("for_negative_step", for_negative_step, N,
         lambda rng: {"n": integers(rng, N, -5, 12), "out": np.zeros(N, np.int32)},
         _neg_step_ref, ("out",)),
    Case("nested_loops", nested_loops, N,
         lambda rng: {"n": integers(rng, N, 0, 9), "out": np.zeros(N, np.int32)},
         _nested_ref, ("out",)),
    Case("while_data_dependent", while_collatz, N,
         lambda rng: {"a": integers(rng, N, 1, 60), "steps": np.zeros(N, np.int32)},
         _collatz_ref, ("steps",)),
    Case("loop_break", loop_break, N,
         lambda rng: {"a": uniform(rng, (N, 8), 0, 1), "first": np.zeros(N, np.int32)},
         _break_ref, ("first",)),
    Case("loop_continue", loop_continue, N,
         lambda rng: {"a": uniform(rng, (N, 9), -1, 1), "out": np.zeros(N, np.float32)},
         _continue_ref, ("out",)),
    Case("while_break_continue", while_break_continue, N,
         lambda rng: {"a": integers(rng, N, 0, 15), "out": np.zeros(N, np.int32)},
         _wbc_ref, ("out",)),
    Case("early_return_kernel", early_return, N,
         lambda rng: {"a": uniform(rng, N, -1, 5), "out": np.zeros(N, np.float32)},
         _early_ref, ("out",)),
    Case("static_loop_unrolled", static_unroll, N,
         lambda rng: {"a": uniform(rng, (N, 4), -1, 1), "out": np.zeros(N, np.float32)},
         lambda ins: {"out": f64(ins["a"]) @ np.array([1.0, 2.0, 3.0, 4.0])}, ("out",)),
]  # fmt: skip
