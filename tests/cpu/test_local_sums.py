"""Range-local sums (``kdsl.backends.cpu.local_sums``): atomic adds into one element
from every thread are summed per range and added with one atomic per range.

Which atomics qualify is checked on the IR (``find_sites``); what they compute is
checked against the interpreter (one atomic per thread) and NumPy, inline and split
over the thread pool, forward and in adjoints.
"""

import numpy as np
import pytest

import kdsl as wp
from kdsl.backends.cpu.local_sums import find_sites
from kdsl.compiler import adjoint_module
from tests.device_targets import TARGETS


@wp.kernel
def squares(x: wp.array(dtype=float), total: wp.array(dtype=float)):
    i = wp.tid()
    wp.atomic_add(total, 0, x[i] * x[i])


@wp.kernel
def big_ones(x: wp.array(dtype=int), out: wp.array(dtype=int), k: int, limit: int):
    i = wp.tid()
    if x[i] > limit:
        wp.atomic_add(out, k, x[i])


@wp.kernel
def vec_total(x: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec3)):
    wp.atomic_add(out, 0, x[wp.tid()])


@wp.kernel
def skipped(x: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    if x[i] > 1.0e30:
        wp.atomic_add(out, 0, x[i])


@wp.kernel
def read_too(x: wp.array(dtype=float), out: wp.array(dtype=float), seen: wp.array(dtype=float)):
    i = wp.tid()
    wp.atomic_add(out, 0, x[i])
    seen[i] = out[1]


@wp.kernel
def per_thread(x: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    wp.atomic_add(out, i % 4, x[i])


@wp.kernel
def old_value_used(x: wp.array(dtype=float), out: wp.array(dtype=float),
                   olds: wp.array(dtype=float)):  # fmt: skip
    i = wp.tid()
    olds[i] = wp.atomic_add(out, 0, x[i])


@wp.kernel
def subtract(x: wp.array(dtype=float), out: wp.array(dtype=float)):
    wp.atomic_sub(out, 0, x[wp.tid()])


@wp.kernel
def halves(x: wp.array(dtype=wp.float16), out: wp.array(dtype=wp.float16)):
    wp.atomic_add(out, 0, x[wp.tid()])


@wp.kernel
def scale_by_shared(x: wp.array(dtype=float), c: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = x[i] * c[0]


@wp.kernel
def bounded(x: wp.array(dtype=int), out: wp.array(dtype=int), n: int):
    # A bounds test on tid: the cpu backend also runs an interior copy of the body.
    i = wp.tid()
    if i < n:
        wp.atomic_add(out, 0, x[i])


def _sites(kernel):
    func = kernel.build_module().get_func(kernel.key)
    return find_sites(func.regions[0].block)


@pytest.mark.parametrize(
    ("kernel", "count"),
    [(squares, 1), (big_ones, 1), (vec_total, 1), (skipped, 1), (read_too, 0), (per_thread, 0),
     (old_value_used, 0), (subtract, 0), (halves, 0)],
)  # fmt: skip
def test_which_atomics_are_summed_per_range(kernel, count):
    assert len(_sites(kernel)) == count


def test_the_summed_atomic_runs_once_per_range():
    from kdsl.backends.cpu import BACKEND

    text = BACKEND.emit(squares.build_module(), "llvm-ir-unopt", {}, False)
    flushes = text.count("sum.flush:")
    assert flushes >= 1 and text.count("atomicrmw") == flushes


def test_the_adjoint_of_a_parameter_every_thread_reads_is_summed_per_range():
    module = adjoint_module(scale_by_shared)
    adj = [f for f in module.funcs if f.attrs["sym_name"] != scale_by_shared.key]
    assert any(find_sites(f.regions[0].block) for f in adj)


@pytest.mark.parametrize(("dev", "backend"), TARGETS)
def test_sums_match_one_atomic_per_thread(dev, backend, split):
    rng = np.random.default_rng(3)
    xs = rng.standard_normal(5000).astype(np.float32)
    total = wp.array(np.array([0.25], np.float32), device=dev)
    wp.launch(squares, len(xs), [wp.array(xs, device=dev), total], device=dev, backend=backend)
    np.testing.assert_allclose(total.numpy()[0], 0.25 + np.sum(xs.astype(np.float64) ** 2),
                               rtol=1e-5)  # fmt: skip

    xi = np.arange(3000, dtype=np.int32)
    out = wp.array(np.array([7, 7, 7], np.int32), device=dev)
    wp.launch(big_ones, len(xi), [wp.array(xi, device=dev), out, 2, 100], device=dev,
              backend=backend)  # fmt: skip
    np.testing.assert_array_equal(out.numpy(), [7, 7, 7 + int(xi[xi > 100].sum())])

    out = wp.zeros(1, dtype=int, device=dev)
    wp.launch(bounded, len(xi), [wp.array(xi, device=dev), out, 2500], device=dev,
              backend=backend)  # fmt: skip
    np.testing.assert_array_equal(out.numpy(), [int(xi[:2500].sum())])

    xv = np.arange(3 * 700, dtype=np.float32).reshape(700, 3)
    ov = wp.zeros(1, dtype=wp.vec3, device=dev)
    wp.launch(vec_total, 700, [wp.array(xv, dtype=wp.vec3, device=dev), ov], device=dev,
              backend=backend)  # fmt: skip
    np.testing.assert_array_equal(ov.numpy()[0], xv.sum(axis=0))  # exact: integers in f32


@pytest.mark.parametrize("split", ["inline"], indirect=True)
@pytest.mark.parametrize(("dev", "backend"), TARGETS)
def test_one_range_from_zero_gives_the_sequential_sum_exactly(dev, backend, split):
    xs = np.random.default_rng(5).standard_normal(1000).astype(np.float32)
    total = wp.zeros(1, dtype=float, device=dev)
    wp.launch(squares, 1000, [wp.array(xs, device=dev), total], device=dev, backend=backend)
    expect = np.float32(0.0)
    for v in xs:
        expect = np.float32(expect + v * v)
    if dev != "cpu":  # threads add in any order on a GPU
        np.testing.assert_allclose(total.numpy()[0], expect, rtol=1e-5)
    else:
        assert total.numpy()[0] == expect


@pytest.mark.parametrize(("dev", "backend"), TARGETS)
def test_a_site_no_thread_reaches_leaves_memory_as_it_was(dev, backend, split):
    out = wp.array(np.array([-0.0], np.float32), device=dev)
    wp.launch(skipped, 5000, [wp.zeros(5000, dtype=float, device=dev), out], device=dev,
              backend=backend)  # fmt: skip
    assert np.signbit(out.numpy()[0]) and out.numpy()[0] == 0.0


@pytest.mark.parametrize(("dev", "backend"), TARGETS)
def test_gradient_of_a_shared_parameter(dev, backend, split):
    xs = np.linspace(-1.0, 2.0, 4100).astype(np.float32)
    x = wp.array(xs, device=dev, requires_grad=True)
    c = wp.array(np.array([3.0], np.float32), device=dev, requires_grad=True)
    y = wp.zeros(len(xs), dtype=float, device=dev, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(scale_by_shared, len(xs), [x, c, y], device=dev, backend=backend)
    tape.backward(grads={y: wp.ones(len(xs), dtype=float, device=dev)})
    np.testing.assert_allclose(c.grad.numpy()[0], xs.astype(np.float64).sum(), rtol=1e-4)
    np.testing.assert_array_equal(x.grad.numpy(), np.full(len(xs), 3.0, np.float32))


def test_debug_builds_keep_one_atomic_per_thread_and_agree():
    xi = np.arange(3000, dtype=np.int32)
    out = wp.zeros(3, dtype=int)
    old = wp.config.mode
    wp.config.mode = "debug"
    try:
        wp.launch(big_ones, len(xi), [wp.array(xi), out, 2, 100], backend="cpu")
    finally:
        wp.config.mode = old
    np.testing.assert_array_equal(out.numpy(), [0, 0, int(xi[xi > 100].sum())])
