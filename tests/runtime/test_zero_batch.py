"""``tape.zero()`` in one pass per device (``kdsl.runtime.zero_batch``): exactly the
tape's gradients become zero, after arrays are added, replaced or dropped too."""

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslError
from kdsl.runtime import zero_batch
from kdsl.runtime.zero_batch import zero_arrays, zero_spans_launch

cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")
DEVICES = ["cpu", pytest.param("cuda:0", marks=cuda)]


@wp.struct
class Pair:
    a: float
    b: wp.vec3


def _filled(device, shape, dtype=float, value=1.0):
    a = wp.zeros(shape, dtype=dtype, device=device)
    a.fill_(value)
    return a


def _mixed(device):
    """Arrays of several kinds: scalars, vectors, 2-d, a strided view, an odd-sized f16,
    an empty one, structs."""
    base = _filled(device, (6, 4))
    return [
        _filled(device, 37),
        _filled(device, 5, dtype=wp.vec3),
        _filled(device, (3, 5)),
        base[:, 1],  # strided: zeroed through zero_(), the rest of base untouched
        _filled(device, 3, dtype=wp.float16),  # 6 bytes: not whole words
        wp.zeros(0, device=device),
        _filled(device, 4, dtype=wp.int64, value=7),
        wp.array([Pair(a=2.0, b=wp.vec3(1.0, 2.0, 3.0))] * 3, dtype=Pair, device=device),
    ], base


def _total(a):
    data = a.numpy()
    if data.dtype.names:
        return sum(float(np.abs(data[n]).sum()) for n in data.dtype.names)
    return float(np.abs(data.astype(np.float64)).sum())


@pytest.mark.parametrize("device", DEVICES)
def test_zero_batch_zeroes_exactly_the_given_arrays(device):
    arrays, base = _mixed(device)
    bystander = _filled(device, 8)
    made = zero_batch.made
    for _ in range(2):  # the first call plans, the second reuses the plan
        for a in arrays[:-1]:
            a.fill_(3)
        zero_arrays(arrays)
        assert [_total(a) for a in arrays] == [0.0] * len(arrays)
        np.testing.assert_array_equal(base.numpy()[:, [0, 2, 3]], 1.0)
        np.testing.assert_array_equal(bystander.numpy(), 1.0)
    assert zero_batch.made == made + 1


@pytest.fixture(params=["memset", "kernel"])
def cpu_path(request, monkeypatch):
    """The cpu's own path (memset), or the zero kernel's (what CUDA devices take)."""
    if request.param == "kernel":
        monkeypatch.setattr(zero_batch, "KERNEL_KINDS", frozenset({"cpu", "cuda"}))
    return request.param


def test_zero_batch_on_the_cpu_both_paths(cpu_path):
    arrays, base = _mixed("cpu")
    many = [_filled("cpu", n) for n in (1, 2, 3, 700)]
    zero_batch.forget_plans()
    for _ in range(2):
        for a in arrays[:-1] + many:
            a.fill_(3)
        zero_arrays(arrays + many)
        assert [_total(a) for a in arrays + many] == [0.0] * (len(arrays) + 4)
        np.testing.assert_array_equal(base.numpy()[:, [0, 2, 3]], 1.0)
    few = many[:2]  # under MIN_BATCH: array by array
    for a in few:
        a.fill_(1)
    zero_arrays(few)
    assert [_total(a) for a in few] == [0.0, 0.0]


@pytest.mark.parametrize("device", DEVICES)
def test_zero_batch_replans_when_the_list_changes(device):
    first = [_filled(device, 16) for _ in range(6)]
    zero_arrays(first)
    extra = _filled(device, 9)
    for a in first:
        a.fill_(2)
    zero_arrays([*first, extra])  # one more array
    assert [_total(a) for a in (*first, extra)] == [0.0] * 7
    kept = first[::2]
    for a in first:
        a.fill_(5)
    zero_arrays(kept)
    assert [_total(a) for a in kept] == [0.0] * len(kept)
    assert [_total(a) for a in first[1::2]] == [5.0 * 16] * 3  # not in the list
    zero_arrays([])  # nothing to do


@pytest.mark.parametrize("device", DEVICES)
def test_a_plan_never_serves_arrays_that_replaced_freed_ones(device):
    """A freed array's id may be reused by a new one, so the new list may look up the
    old list's plan: it must check its arrays and not zero the old memory instead. (The
    reuse is forced here: the old plan is filed under the new arrays' ids.)"""
    old = [_filled(device, 64) for _ in range(5)]
    zero_arrays(old)
    new = [_filled(device, 64) for _ in range(5)]
    for a in old:
        a.fill_(2.0)
    zero_batch._PLANS[tuple(map(id, new))] = zero_batch._PLANS[tuple(map(id, old))]
    zero_arrays(new)
    assert [_total(a) for a in new] == [0.0] * 5
    assert [_total(a) for a in old] == [128.0] * 5


def test_plans_are_shared_by_tapes_and_bounded(monkeypatch):
    monkeypatch.setattr(zero_batch, "MAX_PLANS", 2)
    zero_batch.forget_plans()
    lists = [[_filled("cpu", 8) for _ in range(3)] for _ in range(3)]
    made = zero_batch.made
    for arrays in lists:
        zero_arrays(arrays)
    zero_arrays(lists[2])  # kept
    assert zero_batch.made == made + 3
    zero_arrays(lists[0])  # dropped (MAX_PLANS): made again
    assert zero_batch.made == made + 4
    # two tapes over the same gradients share one plan
    xs = [wp.zeros(4, dtype=float, requires_grad=True) for _ in range(4)]
    made = zero_batch.made
    for _ in range(3):
        tape = wp.Tape()
        for x in xs:
            tape.get_adjoint(x)
            x.grad.fill_(1.0)
        tape.zero()
        assert [_total(x.grad) for x in xs] == [0.0] * 4
    assert zero_batch.made == made + 1


def _flight(device, steps, extra_grad=None):
    """A small taped computation whose gradients are then non-zero."""

    tape = wp.Tape()
    xs = [_filled(device, 8) for _ in range(steps + 1)]
    for x in xs:
        x.requires_grad = True
    with tape:
        for k in range(steps):
            wp.launch(_scale, 8, [xs[k], 2.0, xs[k + 1]], device=device)
    for x in xs:
        x.grad.fill_(1.5)
    return tape, xs


@wp.kernel
def _scale(x: wp.array(dtype=float), s: float, y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = x[i] * s


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda:0", marks=cuda)])
def test_tape_zero_after_gradients_are_added_replaced_and_reset(device, cpu_path):
    tape, xs = _flight(device, 6)
    assert len(tape.gradients) == 7
    tape.zero()
    assert [_total(x.grad) for x in xs] == [0.0] * 7
    # A new array recorded later joins; a replaced .grad is what gets zeroed.
    more = _filled(device, 8)
    more.requires_grad = True
    with tape:
        wp.launch(_scale, 8, [xs[-1], 3.0, more], device=device)
    old = xs[0].grad
    xs[0].grad = _filled(device, 8, value=4.0)
    tape.get_adjoint(xs[0])
    for x in (*xs, more):
        x.grad.fill_(2.0)
    old.fill_(9.0)
    tape.zero()
    assert [_total(x.grad) for x in (*xs, more)] == [0.0] * 8
    # the old gradient is no longer the tape's: zero() leaves it alone
    np.testing.assert_array_equal(old.numpy(), 9.0)
    tape.reset()
    assert tape.gradients == {}
    np.testing.assert_array_equal(old.numpy(), 9.0)


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda:0", marks=cuda)])
def test_zero_spans_launch_zeroes_only_its_spans(device):
    """The zero kernel itself (the CUDA path of zero_arrays), also on the cpu backend:
    sizes below, at and above the kernel's width, neighbours untouched."""
    data = [np.arange(1, n + 1, dtype=np.float32) for n in (1, 5, 300, 17)]
    arrays = [wp.array(d, device=device) for d in data]
    spans = [arrays[1].memory_span(), arrays[2].memory_span(), arrays[3].memory_span()]
    run = zero_spans_launch(wp.get_device(device), spans)
    run()
    run()
    np.testing.assert_array_equal(arrays[0].numpy(), data[0])
    for a in arrays[1:]:
        np.testing.assert_array_equal(a.numpy(), 0.0)


def test_zero_spans_launch_width_is_capped(monkeypatch):
    """An array longer than the kernel's width: each thread stores several words."""
    monkeypatch.setattr(zero_batch, "MAX_WIDTH", 64)
    a = _filled("cpu", 1000)
    b = _filled("cpu", 3)
    zero_spans_launch(wp.get_device("cpu"), [a.memory_span(), b.memory_span()])()
    assert _total(a) == 0.0 and _total(b) == 0.0


@pytest.mark.parametrize(
    "spans, what",
    [([], "no spans"), ([(2, 8)], "(2, 8)"), ([(8, 6)], "(8, 6)"), ([(8, 0)], "(8, 0)")],
)
def test_zero_spans_launch_refuses_bad_spans(spans, what):
    with pytest.raises(KdslError, match="4-byte aligned") as e:
        zero_spans_launch(wp.get_device("cpu"), spans)
    assert what in str(e.value)


def test_zero_kernel_compiles_for_cuda():
    """Compile-only (no GPU needed): the zero kernel through NVRTC (sm_90)."""
    pytest.importorskip("cupy_backends.cuda.libs.nvrtc")
    from kdsl.backends.cuda import nvrtc
    from kdsl.backends.cuda.lower import generate
    from kdsl.passes import DEFAULT_PIPELINE, run_pipeline

    m = zero_batch._zero_words.build_module()
    run_pipeline(m, DEFAULT_PIPELINE)
    nvrtc.compile_source(generate(m, [zero_batch._zero_words.key]).text, "sm_90")


def test_a_kept_plan_does_not_keep_its_arrays_alive():
    import gc
    import weakref

    # Strided views take array.zero_ in the plan: their steps must not hold them.
    arrays = [wp.zeros((4, 4), dtype=float, device="cpu")[:, 1] for _ in range(3)]
    zero_arrays(arrays)
    refs = [weakref.ref(a) for a in arrays]
    del arrays
    gc.collect()
    assert all(r() is None for r in refs)
