"""Lane blocks (``kdsl/backends/cpu/lane_blocks.py``): a thread loop around one uniform
loop runs in blocks of threads, the uniform loop outside a loop over the lanes.

Which kernels qualify is checked on the IR (``lane_plan``); that the lane loops are in
the LLVM IR and vectorize; and that the results are the very bits of a debug build
(which runs the plain thread loop), for sizes around the block size, inline and split
over the pool, and against NumPy on every target.
"""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.backends.cpu import lane_blocks
from kdsl.backends.cpu.lower import lower_kernels
from kdsl.compiler import lower
from tests.device_targets import TARGETS


def _waves(
    x: wp.array(dtype=float),
    k: wp.array(dtype=float),
    scale: float,
    out: wp.array(dtype=wp.vec2),
    peak: wp.array(dtype=float),
):
    i = wp.tid()
    xi = x[i]
    shift = 0.0
    if xi > 0.5:
        shift = scale
    acc = wp.vec2(shift, 0.0)
    top = -1.0e30
    for w in range(k.shape[0]):
        theta = k[w] * xi + float(i) * 0.001
        acc = acc + wp.vec2(wp.sin(theta), wp.cos(theta))
        top = wp.max(top, theta)
    out[i] = acc * xi
    peak[i] = top + shift


waves = wp.kernel(_waves)
waves_debug = wp.kernel(debug=True)(_waves)


def _countdown(x: wp.array(dtype=float), n: int, out: wp.array(dtype=float)):
    i = wp.tid()
    acc = x[i]
    for w in range(n - 1, -1, -1):
        acc = acc * 0.5 + x[i] * float(w)
    out[i] = acc


countdown = wp.kernel(_countdown)
countdown_debug = wp.kernel(debug=True)(_countdown)


@wp.kernel
def bound_per_thread(x: wp.array(dtype=float), n: wp.array(dtype=int), out: wp.array(dtype=float)):
    i = wp.tid()
    acc = 0.0
    for _w in range(n[i]):
        acc = acc + x[i]
    out[i] = acc


@wp.kernel
def two_loops(x: wp.array(dtype=float), n: int, out: wp.array(dtype=float)):
    i = wp.tid()
    acc = 0.0
    for _w in range(n):
        acc = acc + x[i]
    for _w in range(n):
        acc = acc * x[i]
    out[i] = acc


@wp.kernel
def nested(x: wp.array(dtype=float), n: int, out: wp.array(dtype=float)):
    i = wp.tid()
    acc = 0.0
    for _w in range(n):
        for v in range(n):
            acc = acc + x[i] * float(v)
    out[i] = acc


@wp.kernel
def with_atomic(x: wp.array(dtype=float), n: int, out: wp.array(dtype=float)):
    i = wp.tid()
    acc = 0.0
    for _w in range(n):
        acc = acc + x[i]
    wp.atomic_add(out, 0, acc)


@wp.kernel
def grid_2d(x: wp.array2d(dtype=float), n: int, out: wp.array2d(dtype=float)):
    i, j = wp.tid()
    acc = 0.0
    for _w in range(n):
        acc = acc + x[i, j]
    out[i, j] = acc


def _func(kernel):
    return kernel.build_module().get_func(kernel.key)


def test_which_kernels_get_lane_blocks():
    plan = lane_blocks.lane_plan(_func(waves))
    assert plan is not None and plan.loop.name == "scf.for"
    assert lane_blocks.lane_plan(_func(countdown)) is not None
    for kernel in (bound_per_thread, two_loops, nested, with_atomic, grid_2d):
        assert lane_blocks.lane_plan(_func(kernel)) is None, kernel.key


def test_prologue_values_the_loop_reads_cross_in_lane_arrays():
    plan = lane_blocks.lane_plan(_func(waves))
    names = {v.name_hint for v in plan.crossing}
    assert {"i", "xi", "shift"} <= names  # tid, the load and the if's result
    assert not any(op.name == "kd.tid" for op in plan.uniform)


def _ir(kernel, stage: str = "llvm-ir-unopt") -> str:
    from kdsl.backends.cpu import BACKEND

    return lower(BACKEND, kernel.build_module(), stage)


def _host_has(feature: str) -> bool:
    import llvmlite.binding as llvm

    return bool(llvm.get_host_cpu_features().get(feature, False))


def test_the_ir_has_the_three_lane_loops(cpu_backend):
    text = _ir(waves)
    for name in ("lane.pro.head", "lane.step.head", "lane.epi.head", "uniform.head"):
        assert name in text
    assert "thread.head" in text  # the threads after the last whole block
    debug = str(lower_kernels(waves_debug.build_module(), [waves_debug.key], debug=True).llmod)
    assert "lane." not in debug


@pytest.mark.skipif(not _host_has("avx2"), reason="the vectorizer's choice depends on the host")
def test_the_lane_loops_vectorize(cpu_backend):
    assert _ir(waves, "llvm-ir").count("vector.body") >= 3


def _run_waves(kernel, n: int, waves_k: np.ndarray, dev: str = "cpu", backend=None):
    x = np.random.default_rng(n).uniform(0.0, 1.0, n).astype(np.float32)
    out = wp.zeros(n, dtype=wp.vec2, device=dev)
    peak = wp.zeros(n, dtype=float, device=dev)
    wp.launch(kernel, n, [wp.array(x, device=dev), wp.array(waves_k, device=dev), 2.5, out, peak],
              device=dev, backend=backend)  # fmt: skip
    return x, out.numpy(), peak.numpy()


@pytest.mark.parametrize("n", [1, 15, 16, 17, 33, 1003])
def test_same_bits_as_the_plain_thread_loop(n, split):
    k = np.linspace(0.5, 40.0, 7).astype(np.float32)
    _, out, peak = _run_waves(waves, n, k)
    _, out_d, peak_d = _run_waves(waves_debug, n, k)
    np.testing.assert_array_equal(out.view(np.uint32), out_d.view(np.uint32))
    np.testing.assert_array_equal(peak.view(np.uint32), peak_d.view(np.uint32))


@pytest.mark.parametrize("trips", [0, 1, 5])
def test_a_loop_counting_down_or_not_at_all(trips, split):
    x = np.random.default_rng(trips).standard_normal(50).astype(np.float32)
    outs = []
    for kernel in (countdown, countdown_debug):
        out = wp.zeros(50, dtype=float)
        wp.launch(kernel, 50, [wp.array(x), trips, out])
        outs.append(out.numpy())
    np.testing.assert_array_equal(outs[0].view(np.uint32), outs[1].view(np.uint32))
    expect = x.astype(np.float64)
    for w in range(trips - 1, -1, -1):
        expect = expect * 0.5 + x * w
    np.testing.assert_allclose(outs[0], expect, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize(("dev", "backend"), TARGETS)
def test_results_on_every_target(dev, backend, split):
    k = np.linspace(0.5, 9.0, 5).astype(np.float32)
    x, out, peak = _run_waves(waves, 100, k, dev, backend)
    x64, k64 = x.astype(np.float64), k.astype(np.float64)
    theta = k64[None, :] * x64[:, None] + np.arange(100)[:, None] * 0.001
    shift = np.where(x64 > 0.5, 2.5, 0.0)
    expect = np.stack([shift + np.sin(theta).sum(1), np.cos(theta).sum(1)], axis=1) * x64[:, None]
    np.testing.assert_allclose(out, expect, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(peak, theta.max(1) + shift, rtol=1e-6)
