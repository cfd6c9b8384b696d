"""The adjoint pass and adjoint launches: what the gradient conformance cases do not cover.

The gradients of every builtin and control-flow form are conformance cases
(``kdsl/testing/cases/gradients.py``, run on every backend); here are exact
values, the tape machinery and the error paths.
"""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.autograd import gradcheck
from kdsl.errors import KdslError, KdslGradientWarning
from kdsl.runtime.adjoint import launch_adjoint
from kdsl.testing.cases import gradients
from kdsl.testing.cases.gradients import dynamic_loop, two_d, while_loop

F = wp.float64
BACKENDS = ["interp", "cpu"]


def _x(n=6, lo=0.2, hi=1.2, seed=1):
    return np.random.default_rng(seed).uniform(lo, hi, n)


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
    x = wp.array(np.array([1.3, 1.9, 1.05, 1.5]), dtype=F, requires_grad=True)
    out = wp.zeros(4, dtype=F, requires_grad=True)
    assert gradcheck(while_loop, 4, [x], [out], eps=1e-6, atol=1e-7, rtol=1e-6,
                     show_summary=False, backend="cpu")  # fmt: skip


def test_tape_budget_gives_a_clear_error(monkeypatch):
    monkeypatch.setattr(wp.config, "max_tape_bytes", 64)
    arrs = [wp.array(_x(), dtype=F), 100, wp.zeros(6, dtype=F)]
    with pytest.raises(KdslError, match="max_tape_bytes") as info:
        launch_adjoint(dynamic_loop, 6, arrs, [wp.zeros(6, dtype=F), None, wp.ones(6, dtype=F)],
                       backend="cpu")  # fmt: skip
    assert "gradients.py" in str(info.value)  # names the loop's source line


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


def test_cli_prints_the_adjoint_stage():
    import subprocess
    import sys

    target = f"{gradients.__file__}:gather_in_loop"
    proc = subprocess.run([sys.executable, "-m", "kdsl.cli", "ir", target, "--stage", "adjoint"],
                          capture_output=True, text=True, timeout=120)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    assert "__adj(" in out and "__count(" in out  # the adjoint and its tape counter
    # Reads of other threads' elements became atomic adds into the gradient.
    assert 'kd.atomic_rmw' in out and '{kind = "add"}' in out
    assert "tape_slots = [-1]" in out  # a run-time trip count


def test_elements_a_thread_owns_get_plain_gradient_updates():
    # x is only ever indexed by the thread index: no other thread touches adj_x[i].
    from kdsl.ir import print_module
    from kdsl.runtime.adjoint import adjoint_kernel

    text = print_module(adjoint_kernel(dynamic_loop).build_module())
    assert "kd.atomic_rmw" not in text
    assert "kd.store" in text and "%adj_x" in text



def test_print_and_cas_are_not_replayed(capfd):
    @wp.kernel
    def noisy(x: wp.array(dtype=F), flags: wp.array(dtype=int), out: wp.array(dtype=F)):
        i = wp.tid()
        wp.atomic_cas(flags, 0, 0, 1)
        wp.printf("thread %d\n", i)
        out[i] = x[i] * x[i]

    x = wp.array(np.array([1.0, 2.0]), dtype=F)
    flags = wp.zeros(1, dtype=int)
    out = wp.zeros(2, dtype=F)
    wp.launch(noisy, 2, [x, flags, out], backend="cpu")
    capfd.readouterr()
    gx = wp.zeros(2, dtype=F)
    launch_adjoint(noisy, 2, [x, flags, out], [gx, None, wp.ones(2, dtype=F)], backend="cpu")
    assert "thread" not in capfd.readouterr().out  # the backward pass prints nothing
    np.testing.assert_allclose(gx.numpy(), [2.0, 4.0])
    assert flags.numpy()[0] == 1
