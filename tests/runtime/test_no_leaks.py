"""Long runs of the hot paths leave no Python objects behind (counted, not timed).

Each case warms up (plans, prepared launches, caches), then counts the objects the
collector tracks before and after many more iterations. Any per-iteration leak of a
container (a list, a dict, a prepared launch, a recorded graph) shows as growth
proportional to the count; a small slack absorbs interpreter noise.
"""

import gc

import numpy as np
import pytest

import kdsl as wp
from kdsl.runtime.launch import launch_plan
from kdsl.runtime.launch_reuse import MAX_ENTRIES, MAX_SEEN

SLACK = 20


@wp.kernel
def bump(a: wp.array(dtype=float), b: wp.array(dtype=float)):
    i = wp.tid()
    b[i] = a[i] + 1.0


@wp.kernel
def bump_by(a: wp.array(dtype=float), b: wp.array(dtype=float), s: float):
    i = wp.tid()
    b[i] = a[i] + s


def _settle() -> int:
    """The tracked objects, counted with the bounded reuse tables emptied (their fill
    level at the moment of counting varies by up to 8 prepared launches)."""
    for kernel in (bump, bump_by):
        for plan in getattr(kernel, "_kdsl_plans", {}).values():
            plan.reuse.clear()
    gc.collect()
    return len(gc.get_objects())


def _growth(body, count: int) -> int:
    body(max(1, count // 4))
    before = _settle()
    body(count)
    return _settle() - before


@pytest.mark.parametrize("backend", ["cpu", "interp"])
def test_launches_leave_nothing(backend):
    a = wp.array(np.ones(64, np.float32), device="cpu")
    b = wp.zeros(64, dtype=float, device="cpu")

    def body(n):
        for _ in range(n):
            wp.launch(bump, dim=64, inputs=[a, b], device="cpu", backend=backend)

    assert _growth(body, 2000 if backend == "cpu" else 200) <= SLACK


def test_changing_scalars_and_fresh_arrays_keep_the_reuse_tables_bounded():
    a = wp.array(np.ones(8, np.float32), device="cpu")
    sizes = []

    def body(n):
        reuse = launch_plan(bump_by, "cpu", None).reuse
        for k in range(n):
            out = wp.zeros(8, dtype=float, device="cpu")  # a new buffer every launch
            wp.launch(bump_by, dim=8, inputs=[a, out, float(k)], device="cpu")
            sizes.append((len(reuse.entries), len(reuse.seen)))

    assert _growth(body, 1000) <= SLACK
    assert max(e for e, _ in sizes) <= MAX_ENTRIES and max(s for _, s in sizes) <= MAX_SEEN


def test_captures_and_replays_leave_nothing():
    a = wp.array(np.ones(32, np.float32), device="cpu")
    b = wp.zeros(32, dtype=float, device="cpu")

    def body(n):
        for _ in range(n):
            with wp.ScopedCapture(device="cpu") as capture:
                wp.launch(bump, dim=32, inputs=[a, b], device="cpu")
                wp.launch(bump, dim=32, inputs=[b, a], device="cpu")
            wp.capture_launch(capture.graph)

    assert _growth(body, 400) <= SLACK


def test_allocate_and_free_cycles_leave_nothing():
    a = wp.array(np.ones(16, np.float32), device="cpu")

    def body(n):
        for _ in range(n):
            tmp = wp.zeros(4096, dtype=float, device="cpu")
            wp.launch(bump, dim=16, inputs=[a, tmp], device="cpu")
            del tmp

    assert _growth(body, 1000) <= SLACK


@pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")
def test_cuda_launches_captures_and_allocations_leave_nothing():
    import cupy

    dev = "cuda:0"
    a = wp.array(np.ones(256, np.float32), device=dev)
    b = wp.zeros(256, dtype=float, device=dev)

    def body(n):
        for _ in range(n):
            wp.launch(bump, dim=256, inputs=[a, b], device=dev)
            with wp.ScopedCapture(device=dev) as capture:
                wp.launch(bump, dim=256, inputs=[a, b], device=dev)
            wp.capture_launch(capture.graph)
            tmp = wp.zeros(1 << 16, dtype=float, device=dev)
            wp.launch(bump, dim=256, inputs=[a, tmp], device=dev)
            del tmp
        wp.synchronize_device(dev)

    pool = cupy.get_default_memory_pool()
    body(50)
    held = pool.total_bytes()
    assert _growth(body, 400) <= SLACK
    assert pool.total_bytes() <= held * 1.01 + (1 << 20)


def test_taped_launches_and_backward_passes_leave_nothing():
    # The adjoint launches keep a plan per kernel, scratch gradients and prepared
    # launches: all bounded, none growing with the passes.
    a = wp.array(np.ones(16, np.float32), device="cpu", requires_grad=True)
    b = wp.zeros(16, dtype=float, device="cpu", requires_grad=True)
    c = wp.zeros(16, dtype=float, device="cpu")  # no gradient: a scratch one is used

    def body(n):
        for _ in range(n):
            tape = wp.Tape()
            with tape:
                wp.launch(bump, dim=16, inputs=[a, b], device="cpu")
                wp.launch(bump, dim=16, inputs=[b, c], device="cpu")
            tape.backward(grads={b: wp.ones(16, dtype=float, device="cpu")})
            tape.zero()

    assert _growth(body, 400) <= SLACK
