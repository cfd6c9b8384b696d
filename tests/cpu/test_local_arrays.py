"""Thread-local arrays: ``zeros(shape, dtype)`` in kernels (``kd.local_array``), on interp
and cpu against NumPy (and Warp when it is installed), debug bounds checks, the adjoint,
and the errors."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.backends import registry
from kdsl.errors import KdslError, KdslRuntimeError, KdslTypeError
from kdsl.passes.features import analyze_features
from tests.warp_peer import import_warp_cpu

BACKENDS = ["interp", "cpu"]
DEPTH = wp.constant(8)


@pytest.fixture(params=BACKENDS)
def backend(request, cpu_backend):
    return request.param


def make_stack_digits(local):
    """A kernel that pushes the decimal digits of ``n[i]`` on a stack made by ``local``
    (``wp.zeros`` or ``wp.ext.empty``: written before it is read, so either works) and
    pops them back into a number."""

    @wp.kernel
    def stack_digits(n: wp.array(dtype=int), out: wp.array(dtype=int)):
        i = wp.tid()
        stack = local(DEPTH, dtype=int)
        top = 0
        x = n[i]
        while x > 0:
            stack[top] = x % 10
            top += 1
            x = x // 10
        r = 0
        while top > 0:
            top -= 1
            r = r * 10 + stack[top]
        out[i] = r

    return stack_digits


@pytest.mark.parametrize("local", [wp.zeros, wp.ext.empty], ids=["zeros", "ext.empty"])
def test_stack_push_pop(backend, local):
    n = np.array([0, 7, 12, 345, 1000, 98765], dtype=np.int32)
    out = wp.zeros(len(n), dtype=int)
    wp.launch(make_stack_digits(local), len(n), [wp.array(n), out], backend=backend)
    np.testing.assert_array_equal(out.numpy(), n)  # pop order undoes push order


@wp.kernel
def histogram(x: wp.array2d(dtype=float), out: wp.array2d(dtype=int)):
    # A per-thread histogram of one row, with atomics and a dynamic index.
    i = wp.tid()
    h = wp.zeros(shape=4, dtype=int)
    for j in range(x.shape[1]):
        b = wp.clamp(int(x[i, j] * 4.0), 0, 3)
        wp.atomic_add(h, b, 1)
    for b in range(4):
        out[i, b] = h[b]


def test_histogram(backend):
    rng = np.random.default_rng(1)
    x = rng.random((5, 37)).astype(np.float32)
    out = wp.zeros((5, 4), dtype=int)
    wp.launch(histogram, 5, [wp.array(x), out], backend=backend)
    want = np.stack([np.bincount(np.clip((r * 4).astype(int), 0, 3), minlength=4) for r in x])
    np.testing.assert_array_equal(out.numpy(), want)


@wp.func
def row_sums(m: wp.array2d(dtype=wp.vec2), r: wp.array(dtype=float)):
    for a in range(m.shape[0]):
        s = 0.0
        for b in range(m.shape[1]):
            s += m[a, b][0] + m[a, b][1]
        r[a] = s


@wp.kernel
def matrix_2d(x: wp.array(dtype=float), out: wp.array2d(dtype=float)):
    # A 2-d local array of vectors filled here and summed by a @func into a second one.
    i = wp.tid()
    m = wp.zeros((3, 2), dtype=wp.vec2)
    for a in range(3):
        for b in range(2):
            m[a, b] = wp.vec2(x[i] * float(a), float(b))
    r = wp.zeros(3, dtype=float)
    row_sums(m, r)
    v = m[2]  # a view of a local array
    out[i, 0] = r[0]
    out[i, 1] = r[1]
    out[i, 2] = r[2] + v[1][1] + float(len(v))


def test_2d_views_and_func(backend):
    x = np.array([1.0, -2.0, 0.5], dtype=np.float32)
    out = wp.zeros((3, 3), dtype=float)
    wp.launch(matrix_2d, 3, [wp.array(x), out], backend=backend)
    a = np.arange(3, dtype=np.float32)
    want = 2 * x[:, None] * a[None, :] + 1.0
    want[:, 2] += 1.0 + 2.0
    np.testing.assert_allclose(out.numpy(), want, rtol=1e-6)


@wp.kernel
def fresh_zeros(out: wp.array(dtype=float)):
    # Each run of zeros() gives zeros again, also in a loop that wrote the last one.
    i = wp.tid()
    total = 0.0
    for k in range(3):
        a = wp.zeros(2, dtype=float)
        total += a[0] + a[1]
        a[k % 2] = float(k + 1)
        total += a[0] + a[1]
    out[i] = total


def test_fresh_zeros_each_run(backend):
    out = wp.zeros(2, dtype=float)
    wp.launch(fresh_zeros, 2, [out], backend=backend)
    np.testing.assert_array_equal(out.numpy(), [6.0, 6.0])


@wp.kernel(debug=True)
def past_the_end(idx: wp.array(dtype=int), out: wp.array(dtype=float)):
    i = wp.tid()
    a = wp.zeros(4, dtype=float)
    a[idx[i]] = 1.0
    out[i] = a[0]


def test_debug_bounds_check(backend):
    out = wp.zeros(1, dtype=float)
    wp.launch(past_the_end, 1, [wp.array(np.array([3], np.int32)), out], backend=backend)
    assert out.numpy()[0] == 0.0
    with pytest.raises(KdslRuntimeError, match=r"out of bounds.*shape \(4,\)"):
        wp.launch(past_the_end, 1, [wp.array(np.array([4], np.int32)), out], backend=backend)


def test_features_list_local_arrays():
    from kdsl.compiler import lower
    from kdsl.ir import parse_module

    module = parse_module(lower(registry.get_backend("interp"), histogram, "kir-opt"))
    assert "local_arrays" in analyze_features(module)


def test_cpu_promotes_a_constant_indexed_local_array(cpu_backend):
    from kdsl.compiler import lower

    text = lower(cpu_backend, fresh_zeros, "llvm-ir")
    assert "alloca" not in text  # mem2reg/SROA: registers, no stack memory


# --- the adjoint ---------------------------------------------------------------------


def _scaled_by_count(local):
    """The kernel below with its stack made by ``local`` (``wp.zeros`` or ``wp.ext.empty``:
    the stack is written before it is read, so both give the same answers)."""

    @wp.kernel
    def scaled_by_count(x: wp.array(dtype=float), y: wp.array(dtype=float)):
        # The local int stack takes no gradient; the gradient of x flows around it.
        i = wp.tid()
        s = local(4, dtype=int)
        n = 0
        for k in range(4):
            if k <= i:
                s[n] = k
                n += 1
        c = 0
        while n > 0:
            n -= 1
            c += s[n]
        y[i] = x[i] * float(c)

    return scaled_by_count


@pytest.mark.parametrize("local", [wp.zeros, wp.ext.empty], ids=["zeros", "ext.empty"])
def test_adjoint_around_local_arrays(backend, local):
    x = wp.array(np.array([1.0, 2.0, 3.0], np.float32), requires_grad=True)
    y = wp.zeros(3, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(_scaled_by_count(local), 3, [x, y], backend=backend)
    tape.backward(grads={y: wp.array(np.ones(3, np.float32))})
    np.testing.assert_array_equal(y.numpy(), [0.0, 2.0, 9.0])
    np.testing.assert_array_equal(x.grad.numpy(), [0.0, 1.0, 3.0])


@wp.kernel
def through_local(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    a = wp.zeros(2, dtype=float)
    a[0] = x[i] * 2.0
    y[i] = a[0]


def test_gradient_through_a_local_array_is_refused(backend):
    x = wp.array(np.ones(2, np.float32), requires_grad=True)
    y = wp.zeros(2, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(through_local, 2, [x, y], backend=backend)
    with pytest.raises(KdslError, match="cannot differentiate through the local array 'a'"):
        tape.backward(grads={y: wp.array(np.ones(2, np.float32))})


# --- errors ----------------------------------------------------------------------------


def _compile(fn):
    return wp.launch(wp.kernel(fn), 1, [wp.zeros(1, dtype=float)], backend="interp")


def test_shape_must_be_constant():
    def k(out: wp.array(dtype=float)):
        n = out.shape[0]
        a = wp.zeros(n, dtype=float)
        out[0] = a[0]

    with pytest.raises(KdslTypeError, match="compile-time constant") as info:
        _compile(k)
    assert info.value.loc is not None and info.value.loc.line > 0


def test_too_large():
    def k(out: wp.array(dtype=float)):
        a = wp.zeros((200, 200), dtype=float)
        out[0] = a[0, 0]

    with pytest.raises(KdslTypeError, match="160000 bytes, over the limit of 65536"):
        _compile(k)


@pytest.mark.parametrize("dtype", ["array", "str"])
def test_unsupported_dtype(dtype):
    bad = wp.array(dtype=float) if dtype == "array" else str

    def k(out: wp.array(dtype=float)):
        a = wp.zeros(4, dtype=bad)
        out[0] = 0.0

    with pytest.raises(KdslTypeError, match="zeros\\(\\)"):
        _compile(k)


def test_fixedarray_type():
    t = wp.fixedarray(dtype=wp.vec3, shape=(2, 4))
    assert (t.ndim, t.size, t.shape, t.strides) == (2, 8, (2, 4), (48, 12))
    assert t == wp.fixedarray(wp.vec3, (2, 4)) and t.dtype is wp.vec3
    with pytest.raises(KdslError, match="over the limit"):
        wp.fixedarray(float, 1 << 20)


# --- against Warp ------------------------------------------------------------------------


WARP_SOURCE = """
import {lib} as w


@w.kernel
def digits(n: w.array(dtype=int), out: w.array(dtype=int)):
    i = w.tid()
    stack = w.zeros(8, dtype=int)
    h = w.zeros((2, 3), dtype=float)
    top = int(0)
    x = n[i]
    while x > 0:
        stack[top] = x % 10
        h[top % 2, x % 3] += 1.0
        top += 1
        x = x // 10
    r = int(0)
    while top > 0:
        top -= 1
        r = r * 10 + stack[top]
    out[i] = r * 100 + int(h[0, 0] + 2.0 * h[1, 2])
"""


def test_against_warp(cpu_backend, tmp_path, monkeypatch):
    import_warp_cpu()
    import importlib

    monkeypatch.syspath_prepend(str(tmp_path))
    n = np.array([5, 120, 4321, 987654], dtype=np.int32)
    got = {}
    for lib in ("warp", "kdsl"):
        (tmp_path / f"local_{lib}.py").write_text(WARP_SOURCE.format(lib=lib))
        mod = importlib.import_module(f"local_{lib}")
        w = mod.w
        if lib == "warp":
            w.config.quiet = True
        out = w.zeros(len(n), dtype=int, device="cpu")
        w.launch(mod.digits, len(n), [w.array(n, dtype=int, device="cpu"), out], device="cpu")
        got[lib] = out.numpy()
    np.testing.assert_array_equal(got["kdsl"], got["warp"])
