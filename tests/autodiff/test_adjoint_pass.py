"""The adjoint pass end to end: adjoint gradients against central finite differences.

Every kernel is float64 and checked on ``interp`` and ``cpu`` through
``launch_adjoint``: the weighted sum ``L = sum(w * out)`` is differentiated with
respect to every float input array, and compared element by element with central
differences of ``L``. The kernels cover each control-flow form the pass handles.
"""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslError
from kdsl.passes._adjoint import KdslGradientWarning
from kdsl.runtime.adjoint import launch_adjoint

F = wp.float64
BACKENDS = ["interp", "cpu"]


def _run(kernel, dim, args, backend):
    """Forward launch on fresh copies; gives the outputs as NumPy arrays."""
    arrs = [wp.array(a.copy(), dtype=_dtype(a)) if isinstance(a, np.ndarray) else a for a in args]
    wp.launch(kernel, dim, arrs, backend=backend)
    return arrs


def _dtype(a: np.ndarray):
    if a.dtype == np.float64 and a.ndim == 2 and a.shape[1] == 3:
        return wp.vec3d
    return {np.float64: wp.float64, np.int32: wp.int32}[a.dtype.type]


def check_gradients(kernel, dim, args, outputs, backend, rtol=1e-6, atol=1e-8, eps=1e-6):
    """Compare adjoint and finite-difference gradients of ``sum(w * out)``.

    ``args`` holds every kernel argument in order (NumPy arrays or scalars);
    ``outputs`` the indices of output arrays. Gradients are checked for every
    float64 input array not in ``outputs``.
    """
    rng = np.random.default_rng(0)
    weights = {i: rng.uniform(0.5, 1.5, args[i].shape) for i in outputs}

    def loss(values):
        out = _run(kernel, dim, values, backend)
        return sum(float(np.sum(weights[i] * out[i].numpy())) for i in outputs)

    arrs = _run(kernel, dim, args, backend)
    grads = []
    for i, a in enumerate(args):
        if not isinstance(a, np.ndarray):
            grads.append(None)
        elif i in outputs:
            grads.append(wp.array(weights[i], dtype=_dtype(a)))
        else:
            grads.append(wp.zeros(a.shape[0], dtype=_dtype(a)) if a.dtype == np.float64 else None)
    launch_adjoint(kernel, dim, arrs, grads, backend=backend)
    checked = 0
    for i, a in enumerate(args):
        if not isinstance(a, np.ndarray) or i in outputs or a.dtype != np.float64:
            continue
        got = grads[i].numpy().reshape(a.shape)
        want = np.zeros(a.shape)
        for idx in np.ndindex(a.shape):
            plus, minus = list(args), list(args)
            plus[i] = a.copy()
            plus[i][idx] += eps
            minus[i] = a.copy()
            minus[i][idx] -= eps
            want[idx] = (loss(plus) - loss(minus)) / (2 * eps)
        np.testing.assert_allclose(got, want, rtol=rtol, atol=atol, err_msg=f"argument {i}")
        checked += 1
    assert checked, "no input was checked"


# -- kernels ------------------------------------------------------------------------


@wp.kernel
def straight_line(x: wp.array(dtype=F), y: wp.array(dtype=F), out: wp.array(dtype=F)):
    i = wp.tid()
    a = x[i]
    b = y[i]
    out[i] = wp.sin(a * b) + wp.exp(a) / (F(1.0) + b * b) - wp.sqrt(a * a + F(1.0))


@wp.kernel
def vectors(p: wp.array(dtype=wp.vec3d), q: wp.array(dtype=wp.vec3d), out: wp.array(dtype=F)):
    i = wp.tid()
    a = p[i]
    b = q[i]
    c = wp.cross(a, b)
    out[i] = wp.dot(wp.normalize(c), a) + wp.length(a - b) * wp.length_sq(c)


@wp.kernel
def branches(x: wp.array(dtype=F), out: wp.array(dtype=F)):
    i = wp.tid()
    v = x[i]
    r = F(0.0)
    if v > F(0.0):
        r = v * v * F(3.0)
    else:
        r = wp.sin(v)
    out[i] = r * v


@wp.kernel
def static_loop(x: wp.array(dtype=F), out: wp.array(dtype=F)):
    i = wp.tid()
    v = x[i]
    s = F(0.0)
    for _ in range(5):
        s = s * v + wp.cos(s)
    out[i] = s


@wp.kernel
def dynamic_loop(x: wp.array(dtype=F), n: int, out: wp.array(dtype=F)):
    i = wp.tid()
    v = x[i]
    s = F(0.5)
    for _ in range(n):
        s = wp.sin(s * v) + s
    out[i] = s


@wp.kernel
def while_loop(x: wp.array(dtype=F), out: wp.array(dtype=F)):
    # The trip count depends on the data.
    i = wp.tid()
    v = x[i]
    s = F(1.0)
    while s < F(20.0):
        s = s * v + F(0.5)
    out[i] = s * v


@wp.kernel
def break_continue(x: wp.array(dtype=F), n: int, out: wp.array(dtype=F)):
    i = wp.tid()
    v = x[i]
    s = F(0.0)
    for j in range(n):
        if j % 3 == 1:
            continue
        s = s + wp.sin(v * F(j)) * v
        if s > F(2.0):
            break
    out[i] = s


@wp.kernel
def nested_loops(x: wp.array(dtype=F), n: int, out: wp.array(dtype=F)):
    i = wp.tid()
    v = x[i]
    s = F(0.1)
    for j in range(n):
        t = s
        for _ in range(j):
            t = t * F(0.9) + v * F(0.01)
        s = s + wp.tanh(t)
    out[i] = s


@wp.kernel
def gather_in_loop(x: wp.array(dtype=F), n: int, out: wp.array(dtype=F)):
    # Each thread reads many elements: the adjoint scatters with atomics.
    i = wp.tid()
    s = F(0.0)
    for j in range(n):
        s = s + x[(i + j) % n] * F(j + 1) * s + x[j]
    out[i] = s


@wp.kernel
def loop_in_branch(x: wp.array(dtype=F), n: int, out: wp.array(dtype=F)):
    i = wp.tid()
    v = x[i]
    r = v
    if v > F(0.3):
        for _ in range(n):
            r = r * F(0.5) + wp.sqrt(r * r + F(1.0))
    out[i] = r


@wp.kernel
def spring_vec(x0: wp.array(dtype=wp.vec3d), k: wp.array(dtype=F), steps: int,
               out: wp.array(dtype=wp.vec3d)):  # fmt: skip
    # Semi-implicit Euler of a damped spring, carrying vector state.
    i = wp.tid()
    x = x0[i]
    v = wp.vec3d(F(0.0), F(0.0), F(0.0))
    stiff = k[0]
    dt = F(0.01)
    for _ in range(steps):
        f = -stiff * x - F(0.1) * v
        v = v + f * dt
        x = x + v * dt
    out[i] = x


@wp.kernel
def accumulate(x: wp.array(dtype=F), loss: wp.array(dtype=F)):
    i = wp.tid()
    wp.atomic_add(loss, 0, x[i] * x[i] * F(0.5))


@wp.kernel
def two_d(x: wp.array2d(dtype=F), out: wp.array2d(dtype=F)):
    i, j = wp.tid()
    out[i, j] = x[i, j] * x[j, i] + wp.cos(x[i, j])


def _x(n=6, lo=0.2, hi=1.2, seed=1):
    return np.random.default_rng(seed).uniform(lo, hi, n)


CASES = {
    "straight_line": (straight_line, 6, lambda: [_x(), _x(seed=2), np.zeros(6)], [2]),
    "vectors": (
        vectors,
        4,
        lambda: [
            np.random.default_rng(3).uniform(-1, 1, (4, 3)),
            np.random.default_rng(4).uniform(-1, 1, (4, 3)),
            np.zeros(4),
        ],
        [2],
    ),  # fmt: skip
    "branches": (branches, 6, lambda: [_x(lo=-1, hi=1), np.zeros(6)], [1]),
    "static_loop": (static_loop, 6, lambda: [_x(), np.zeros(6)], [1]),
    "dynamic_loop": (dynamic_loop, 6, lambda: [_x(), 7, np.zeros(6)], [2]),
    "while_loop": (while_loop, 6, lambda: [_x(lo=1.3, hi=2.0), np.zeros(6)], [1]),
    "break_continue": (break_continue, 6, lambda: [_x(), 12, np.zeros(6)], [2]),
    "nested_loops": (nested_loops, 4, lambda: [_x(4), 5, np.zeros(4)], [2]),
    "gather_in_loop": (gather_in_loop, 5, lambda: [_x(5, -0.3, 0.3), 5, np.zeros(5)], [2]),
    "loop_in_branch": (loop_in_branch, 6, lambda: [_x(lo=0, hi=1), 4, np.zeros(6)], [2]),
    "spring_vec": (
        spring_vec,
        3,
        lambda: [
            np.random.default_rng(5).uniform(-1, 1, (3, 3)),
            np.array([40.0]),
            50,
            np.zeros((3, 3)),
        ],
        [3],
    ),  # fmt: skip
    "accumulate": (accumulate, 6, lambda: [_x(), np.zeros(1)], [1]),
}


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("name", sorted(CASES))
def test_gradients_match_finite_differences(name, backend):
    kernel, dim, make, outputs = CASES[name]
    check_gradients(kernel, dim, make(), outputs, backend)


@pytest.mark.parametrize("backend", BACKENDS)
def test_two_d_launch(backend):
    x = np.random.default_rng(7).uniform(-1, 1, (3, 3))
    arrs = [wp.array(x, dtype=F), wp.zeros((3, 3), dtype=F)]
    wp.launch(two_d, (3, 3), arrs, backend=backend)
    gx = wp.zeros((3, 3), dtype=F)
    launch_adjoint(two_d, (3, 3), arrs, [gx, wp.array(np.ones((3, 3)), dtype=F)], backend=backend)
    want = np.zeros((3, 3))
    for i in range(3):
        for j in range(3):
            want[i, j] += x[j, i] - np.sin(x[i, j])
            want[j, i] += x[i, j]
    np.testing.assert_allclose(gx.numpy(), want, rtol=1e-12)


def test_dynamic_trip_counts_use_the_counting_function():
    # Threads run different numbers of iterations; the tape is sized by the largest.
    x = np.array([1.3, 1.9, 1.05, 1.5])
    check_gradients(while_loop, 4, [x, np.zeros(4)], [1], "cpu")


def test_tape_budget_gives_a_clear_error(monkeypatch):
    monkeypatch.setattr(wp.config, "max_tape_bytes", 64)
    arrs = [wp.array(_x(), dtype=F), 100, wp.zeros(6, dtype=F)]
    with pytest.raises(KdslError, match="max_tape_bytes") as info:
        launch_adjoint(dynamic_loop, 6, arrs, [wp.zeros(6, dtype=F), None, wp.ones(6, dtype=F)],
                       backend="cpu")  # fmt: skip
    assert "test_adjoint_pass.py" in str(info.value)  # names the loop's source line


def test_enable_backward_false_refuses():
    @wp.kernel(enable_backward=False)
    def fwd_only(x: wp.array(dtype=F)):
        i = wp.tid()
        x[i] = x[i] * F(2.0)

    with pytest.raises(KdslError, match="enable_backward=False"):
        launch_adjoint(fwd_only, 1, [wp.zeros(1, dtype=F)], [None], backend="cpu")


def test_used_atomic_result_is_refused():
    @wp.kernel
    def compact(x: wp.array(dtype=F), count: wp.array(dtype=int), out: wp.array(dtype=F)):
        i = wp.tid()
        slot = wp.atomic_add(count, 0, 1)
        out[slot] = x[i]

    arrs = [wp.zeros(2, dtype=F), wp.zeros(1, dtype=int), wp.zeros(2, dtype=F)]
    with pytest.raises(KdslError, match="atomic_add is used") as info:
        launch_adjoint(compact, 2, arrs, [None, None, None], backend="cpu")
    assert "slot = wp.atomic_add(count, 0, 1)" in str(info.value)


def test_read_after_write_warns_with_the_source_line():
    @wp.kernel
    def in_place(x: wp.array(dtype=F)):
        i = wp.tid()
        x[i] = x[i] * F(2.0)
        x[i] = x[i] + F(1.0)

    arrs = [wp.zeros(2, dtype=F)]
    with pytest.warns(KdslGradientWarning, match="reads array 'x' after writing it") as rec:
        launch_adjoint(in_place, 2, arrs, [wp.zeros(2, dtype=F)], backend="cpu")
    assert "x[i] = x[i] + F(1.0)" in str(rec[0].message)
