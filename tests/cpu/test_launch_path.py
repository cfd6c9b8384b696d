"""The cpu launch path: packed arguments of every kind, prepared launches, threads."""

import threading

import numpy as np
import pytest

import kdsl as wp
from kdsl.backends.cpu import pool
from kdsl.backends.cpu.abi import ArgPacker
from kdsl.ir import types as T


@wp.kernel
def every_scalar(
    b: wp.bool,
    i8: wp.int8,
    u8: wp.uint8,
    i16: wp.int16,
    u16: wp.uint16,
    i32: wp.int32,
    u32: wp.uint32,
    i64: wp.int64,
    u64: wp.uint64,
    f16: wp.float16,
    f32: wp.float32,
    f64: wp.float64,
    ints: wp.array(dtype=wp.int64),
    uints: wp.array(dtype=wp.uint64),
    floats: wp.array(dtype=wp.float64),
):
    ints[0] = wp.int64(i8)
    ints[1] = wp.int64(i16)
    ints[2] = wp.int64(i32)
    ints[3] = i64
    ints[4] = wp.int64(0)
    if b:
        ints[4] = wp.int64(1)
    uints[0] = wp.uint64(u8)
    uints[1] = wp.uint64(u16)
    uints[2] = wp.uint64(u32)
    uints[3] = u64
    floats[0] = wp.float64(f16)
    floats[1] = wp.float64(f32)
    floats[2] = f64


SCALARS = [
    True, np.int8(-7), np.uint8(250), np.int16(-30000), np.uint16(65000), -(2**31),
    np.uint32(2**32 - 1), np.int64(-(2**62)), np.uint64(2**64 - 1), np.float16(1.5),
    np.float32(-2.25), 1e300,
]  # fmt: skip


def _scalar_outputs():
    return wp.zeros(5, dtype=wp.int64), wp.zeros(4, dtype=wp.uint64), wp.zeros(3, dtype=wp.float64)


def _check_scalars(ints, uints, floats):
    assert ints.numpy().tolist() == [-7, -30000, -(2**31), -(2**62), 1]
    assert uints.numpy().tolist() == [250, 65000, 2**32 - 1, 2**64 - 1]
    assert floats.numpy().tolist() == [1.5, -2.25, 1e300]


def test_every_scalar_type_is_packed_exactly():
    outs = _scalar_outputs()
    wp.launch(every_scalar, 1, [*SCALARS, *outs], device="cpu")
    _check_scalars(*outs)


def test_every_scalar_type_through_a_prepared_launch():
    outs = _scalar_outputs()
    cmd = wp.launch(every_scalar, 1, [*SCALARS, *outs], device="cpu", record_cmd=True)
    assert outs[0].numpy().tolist() == [0] * 5  # recorded, not run
    cmd.launch()
    _check_scalars(*outs)


@wp.kernel
def composite(
    v: wp.vec3,
    m: wp.mat22,
    h: wp.vec3h,
    x: wp.array2d(dtype=wp.vec3),
    out: wp.array(dtype=float),
):
    out[0] = v[0] + v[1] * 10.0 + v[2] * 100.0
    out[1] = m[0, 1] + m[1, 0] * 10.0
    out[2] = float(h[2])
    out[3] = x[1, 2][1]
    out[4] = float(x.shape[1])


def test_vectors_matrices_and_strided_arrays_are_packed():
    base = np.arange(4 * 6 * 3, dtype=np.float32).reshape(4, 6, 3)
    view = base[::2, ::2]  # a non-contiguous 2x3 view
    x = wp.array(view, dtype=wp.vec3, copy=False)
    out = wp.zeros(5, dtype=float)
    wp.launch(
        composite,
        1,
        [wp.vec3(1.0, 2.0, 3.0), wp.mat22(1.0, 2.0, 3.0, 4.0), wp.vec3h(0.0, 0.0, 0.5), x, out],
    )
    np.testing.assert_array_equal(out.numpy(), [321.0, 32.0, 0.5, view[1, 2, 1], 3.0])


@wp.kernel
def add_value(a: wp.array(dtype=float), value: float):
    i = wp.tid()
    a[i] = a[i] + value


def test_prepared_launch_sees_changed_parameters_and_dims():
    a = wp.zeros(8, dtype=float)
    cmd = wp.launch(add_value, 8, [a, 1.0], record_cmd=True)
    cmd.launch()
    cmd.set_param_at_index(1, 2.0)
    cmd.launch()
    cmd.set_dim(4)
    cmd.launch()
    np.testing.assert_array_equal(a.numpy(), [5, 5, 5, 5, 3, 3, 3, 3])
    b = wp.zeros(8, dtype=float)
    cmd.set_param_by_name("a", b)
    cmd.launch()
    np.testing.assert_array_equal(b.numpy()[:5], [2, 2, 2, 2, 0])


def test_changed_config_mode_recompiles_in_debug():
    a = wp.zeros(4, dtype=float)
    wp.launch(add_value, 4, [a, 1.0])
    old = wp.config.mode
    wp.config.mode = "debug"
    try:
        wp.launch(add_value, 4, [a, 1.0])  # must still work, through the checked build
    finally:
        wp.config.mode = old
    np.testing.assert_array_equal(a.numpy(), [2, 2, 2, 2])


def test_a_descriptor_follows_a_new_array_at_a_reused_address():
    # The descriptor cache is keyed by buffer identity; a freed buffer's id may be reused.
    for n in (3, 5, 7, 9):
        a = wp.zeros(n, dtype=float)
        wp.launch(add_value, n, [a, 1.0])
        np.testing.assert_array_equal(a.numpy(), np.ones(n))
        del a


def test_launches_from_many_python_threads_at_once():
    n = 1 << 14
    arrays = [wp.zeros(n, dtype=float) for _ in range(8)]
    errors = []
    old = pool.min_parallel, pool.adaptive
    pool.min_parallel, pool.adaptive = 1024, False  # some launches on the pool, some inline

    def work(a):
        try:
            for _ in range(20):
                wp.launch(add_value, n, [a, 1.0])
        except Exception as e:  # pragma: no cover - reported below
            errors.append(e)

    threads = [threading.Thread(target=work, args=(a,)) for a in arrays]
    try:
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    finally:
        pool.min_parallel, pool.adaptive = old
    assert not errors
    for a in arrays:
        np.testing.assert_array_equal(a.numpy(), np.full(n, 20.0, dtype=np.float32))


def test_packer_refuses_structs_and_layout_is_aligned():
    s = T.StructType("S", (("a", T.F32),))
    assert not ArgPacker([s]).supported
    p = ArgPacker([T.F32, T.ArrayType(T.F32, 2), T.VectorType(3, T.F64)])
    assert p.supported
    assert all(off % 16 == 0 for off in p.offsets)
    assert p.offsets[0] >= 8 * 3


def test_set_num_threads_restarts_the_pool():
    a = wp.zeros(1 << 13, dtype=float)
    old_threads, old_min = pool.num_threads(), (pool.min_parallel, pool.adaptive)
    pool.min_parallel, pool.adaptive = 1, False
    try:
        for n in (3, 1, 2):
            pool.set_num_threads(n)
            wp.launch(add_value, a.shape[0], [a, 1.0])
    finally:
        pool.set_num_threads(old_threads)
        pool.min_parallel, pool.adaptive = old_min
    np.testing.assert_array_equal(a.numpy(), np.full(a.shape[0], 3.0, dtype=np.float32))
    with pytest.raises(ValueError):
        pool.set_num_threads(0)


@wp.kernel
def index_2d(out: wp.array2d(dtype=wp.int32)):
    i, j = wp.tid()
    out[i, j] = i * 1000 + j


@wp.kernel
def index_4d(out: wp.array4d(dtype=wp.int32)):
    i, j, k, m = wp.tid()
    out[i, j, k, m] = ((i * 10 + j) * 10 + k) * 10 + m


@pytest.mark.parametrize("threads", [1, 3, 7])
def test_nd_launches_split_mid_row_cover_every_index_once(threads):
    # Chunks of the linear range start and end inside rows; every index must be
    # visited exactly once, with the right components.
    old_threads, old_min = pool.num_threads(), (pool.min_parallel, pool.adaptive)
    pool.set_num_threads(threads)
    pool.min_parallel, pool.adaptive = 1, False
    try:
        out2 = wp.full((5, 7), -1, dtype=wp.int32)
        wp.launch(index_2d, (5, 7), [out2])
        out4 = wp.full((2, 3, 4, 5), -1, dtype=wp.int32)
        wp.launch(index_4d, (2, 3, 4, 5), [out4])
    finally:
        pool.set_num_threads(old_threads)
        pool.min_parallel, pool.adaptive = old_min
    i, j = np.indices((5, 7))
    np.testing.assert_array_equal(out2.numpy(), i * 1000 + j)
    i, j, k, m = np.indices((2, 3, 4, 5))
    np.testing.assert_array_equal(out4.numpy(), ((i * 10 + j) * 10 + k) * 10 + m)


@pytest.fixture
def adaptive_two_threads():
    """Two pool threads, the adaptive choice on, ``min_parallel`` 4096; a recording range
    function: ``(fn, calls)``, ``calls`` the ``(start, end)`` chunks it ran."""
    calls = []

    def fn(start, end, *args):
        calls.append((start, end))

    old = pool.num_threads(), pool.min_parallel, pool.adaptive
    pool.set_num_threads(2)
    pool.min_parallel, pool.adaptive = 4096, True
    try:
        yield fn, calls
    finally:
        pool.set_num_threads(old[0])
        pool.min_parallel, pool.adaptive = old[1:]


def _runs(fn, calls, total, cost):
    """The chunks one ``run_range`` of ``total`` threads ran, sorted."""
    calls.clear()
    pool.run_range(fn, total, cost=cost)
    return sorted(calls)


def test_the_pool_is_chosen_by_measured_cost(adaptive_two_threads):
    # A cheap kernel measured inline stays inline at a size where a heavy one goes to
    # the pool; neither decision changes the results.
    fn, calls = adaptive_two_threads
    cost = pool.RangeCost()
    assert _runs(fn, calls, 100, cost) == [(0, 100)]  # not measured yet, small: inline
    assert cost.seconds_per_thread is not None
    cost.seconds_per_thread = 1e-12  # cheap: 5000 threads still far below the dispatch cost
    assert _runs(fn, calls, 5000, cost) == [(0, 5000)]
    cost.seconds_per_thread = 1.0  # heavy: split over both threads
    assert _runs(fn, calls, 5000, cost) == [(0, 2500), (2500, 5000)]
    assert pool.dispatch_seconds() > 0


def test_a_kernel_whose_pool_launches_cost_more_stays_inline(adaptive_two_threads):
    # The first launch of an unmeasured kernel runs inline to be measured, even above
    # min_parallel; a pool launch that costs more than the model's hand-off is recorded
    # as the kernel's pool overhead, and the kernel then stays inline, trying the pool
    # again every retry_pool_every launches.
    fn, calls = adaptive_two_threads
    cost = pool.RangeCost()
    assert _runs(fn, calls, 5000, cost) == [(0, 5000)]  # not measured yet: inline
    assert cost.seconds_per_thread is not None
    cost.seconds_per_thread = 1e-3  # heavy: the pool
    assert _runs(fn, calls, 5000, cost) == [(0, 2500), (2500, 5000)]
    assert cost.pool_overhead is not None  # measured (0 here: the pool ran quickly)
    cost.pool_overhead = 10.0  # pool launches of this kernel cost 10 s more
    for _ in range(pool.retry_pool_every - 1):
        # Heavy again each time: an inline run folds in the real (tiny, load-dependent) cost.
        cost.seconds_per_thread = 1e-3
        assert _runs(fn, calls, 5000, cost) == [(0, 5000)]
    # Then the pool is tried again, and its (fast) launch lowers the estimate.
    cost.seconds_per_thread = 1e-3
    assert _runs(fn, calls, 5000, cost) == [(0, 2500), (2500, 5000)]
    assert cost.pool_overhead < 10.0


def test_one_fast_pool_launch_replaces_a_slow_estimate():
    # The overhead is the minimum over the last cost_window pool launches: a cheaper
    # measurement counts at once (one good retry brings a kernel back to the pool), a
    # dearer one only once cost_window of them have come since.
    cost = pool.RangeCost()
    cost.seconds_per_thread = 1e-6
    cost.record_pool(1.0 + 1e-3 / 2, 1000, 2)  # 1 s beyond its share of the work
    assert cost.pool_overhead == pytest.approx(1.0)
    cost.record_pool(1e-3 / 2 + 1e-4, 1000, 2)  # then a fast launch: 0.1 ms beyond
    assert cost.pool_overhead == pytest.approx(1e-4)
    cost.record_pool(1e-3 / 2 + 3e-4, 1000, 2)  # a slower one does not count yet
    assert cost.pool_overhead == pytest.approx(1e-4)
    for _ in range(pool.cost_window - 1):
        cost.record_pool(1e-3 / 2 + 3e-4, 1000, 2)
    assert cost.pool_overhead == pytest.approx(3e-4)  # the fast one has left the window


def test_kept_minima_are_the_window_minima():
    # seconds_per_thread and pool_overhead are kept as measurements come (read at every
    # launch); after any mix of launches they are the minima over the last cost_window.
    rng = np.random.default_rng(7)
    cost = pool.RangeCost()
    per, bound, extra = [], [], []
    for step in range(400):
        seconds = float(rng.choice([1e-6, 2e-6, 5e-6, 1e-3])) * rng.uniform(0.5, 1.5)
        if step % 7 == 3 and per:
            spt = min(per[-pool.cost_window:] + bound[-pool.cost_window:])
            extra.append(max(0.0, seconds - spt * 1000 / 2))
            bound.append(seconds * 2 / 1000)
            cost.record_pool(seconds, 1000, 2)
        else:
            per.append(seconds / 1000)
            cost.record(seconds, 1000)
        want = min(per[-pool.cost_window:] + bound[-pool.cost_window:])
        assert cost.seconds_per_thread == pytest.approx(want, rel=1e-12)
        if extra:
            assert cost.pool_overhead == pytest.approx(min(extra[-pool.cost_window:]), rel=1e-12)
    cost.seconds_per_thread = 3e-9  # an injected cost replaces the measurements
    assert cost.seconds_per_thread == 3e-9
    cost.record(1e-6, 1000)
    assert cost.seconds_per_thread == pytest.approx(1e-9)


DISPATCH = 1e-5  # an injected hand-off cost: the line is 2e-5 s on two threads


def test_one_slow_inline_launch_does_not_send_a_cheap_kernel_to_the_pool():
    cost = pool.RangeCost()
    for _ in range(3):
        cost.record(1e-6, 1000)  # 1 us for 1000 threads: far below the line
    assert cost.runs_inline(1000, 2, DISPATCH)
    cost.record(5e-3, 1000)  # one launch the host held up for 5 ms
    assert cost.seconds_per_thread == pytest.approx(1e-9)
    assert cost.runs_inline(1000, 2, DISPATCH)


def test_a_pool_launch_brings_an_inflated_estimate_down():
    # An estimate that came only from a slow launch sends the kernel to the pool; the
    # pool's fast launch bounds the inline cost (2 threads x 1 us) and brings it back.
    cost = pool.RangeCost()
    cost.seconds_per_thread = 5e-3 / 1000
    assert not cost.runs_inline(1000, 2, DISPATCH)
    cost.record_pool(1e-6, 1000, 2)
    assert cost.seconds_per_thread == pytest.approx(2e-9)
    assert cost.runs_inline(1000, 2, DISPATCH)


def test_the_choice_has_hysteresis():
    line = DISPATCH * 2  # n / (n - 1) on two threads
    cost = pool.RangeCost()
    cost.seconds_per_thread = 1.1 * line / 1000  # 10% above the line: stays inline
    assert cost.runs_inline(1000, 2, DISPATCH)
    cost.seconds_per_thread = 1.3 * line / 1000  # past the band: the pool
    assert not cost.runs_inline(1000, 2, DISPATCH) and cost.on_pool
    cost.seconds_per_thread = 0.9 * line / 1000  # 10% below: stays on the pool
    assert not cost.runs_inline(1000, 2, DISPATCH)
    cost.seconds_per_thread = 0.7 * line / 1000  # past the band: inline again
    assert cost.runs_inline(1000, 2, DISPATCH) and not cost.on_pool


def test_a_kernel_held_inline_by_its_overhead_retries_the_pool():
    cost = pool.RangeCost()
    cost.seconds_per_thread = 1e-6  # 1 ms for 1000 threads: the pool by the hand-off alone
    cost.pool_overhead = 1.0  # but its pool launches cost 1 s more
    choices = [cost.runs_inline(1000, 2, DISPATCH) for _ in range(2 * pool.retry_pool_every)]
    tries = [k for k, inline in enumerate(choices) if not inline]
    assert tries == [pool.retry_pool_every - 1, 2 * pool.retry_pool_every - 1]
