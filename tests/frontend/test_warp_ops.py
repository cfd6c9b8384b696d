"""Issue 14, items 2 (constants) and 5 (the missing builtins): behaviour the conformance
cases of ``kdsl.testing.cases.warp_ops`` cannot show (printed output, typing, errors),
on interp and cpu, and cuda where a GPU is present."""

from __future__ import annotations

import math

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslSyntaxError, KdslTypeError

BACKENDS = ("interp", "cpu")
CUDA = pytest.param(
    "cuda", marks=pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA GPU")
)
ALL = (*BACKENDS, CUDA)


def _device(backend: str) -> str:
    return "cuda" if backend == "cuda" else "cpu"


NAMES = ("pi", "tau", "e", "inf", "nan", "half_pi", "ln2", "ln10", "log2e", "log10e", "phi")
VALUES = (math.pi, math.tau, math.e, math.inf, math.nan, math.pi / 2, math.log(2), math.log(10),
          1 / math.log(2), 1 / math.log(10), (1 + 5**0.5) / 2)  # fmt: skip


@pytest.mark.parametrize("name,value", list(zip(NAMES, VALUES)))
def test_constants_are_python_floats_in_both_spellings(name, value):
    for spelling in (name, name.upper()):
        got = getattr(wp, spelling)
        assert type(got) is float
        assert got == pytest.approx(value, rel=1e-15) or (math.isnan(got) and math.isnan(value))


def test_constants_match_warp():
    warp = pytest.importorskip("warp")
    for name in NAMES:
        for spelling in (name, name.upper()):
            a, b = getattr(wp, spelling), getattr(warp, spelling)
            assert a == b or (math.isnan(a) and math.isnan(b)), spelling


@wp.kernel
def constants_in_kernel(f: wp.array(dtype=float), d: wp.array(dtype=wp.float64),
                        flags: wp.array(dtype=int)):  # fmt: skip
    x = wp.pi  # alone: a float32
    f[0] = x
    f[1] = wp.TAU
    d[0] = wp.float64(wp.pi)  # rounded once, to float64
    d[1] = d[2] * wp.e  # takes the float64 operand's type
    flags[0] = int(wp.isinf(wp.INF)) + 2 * int(wp.isnan(wp.nan))


@pytest.mark.parametrize("backend", ALL)
def test_constants_in_kernels_typed_as_warp(backend):
    dev = _device(backend)
    f, d, flags = (
        wp.zeros(2, dtype=float, device=dev),
        wp.array(np.array([0.0, 0.0, 2.0]), device=dev),
        wp.zeros(1, dtype=int, device=dev),
    )
    wp.launch(constants_in_kernel, 1, [f, d, flags], device=dev, backend=backend)
    assert f.numpy().tolist() == [np.float32(math.pi), np.float32(math.tau)]
    assert d.numpy()[:2].tolist() == [math.pi, 2.0 * math.e]
    assert flags.numpy()[0] == 3


@wp.func
def scaled_pi(x: wp.float64) -> wp.float64:
    return x * wp.PI


@wp.kernel
def constant_in_func(d: wp.array(dtype=wp.float64)):
    d[0] = scaled_pi(d[0])


def test_constants_in_functions():
    d = wp.array(np.array([2.0]))
    wp.launch(constant_in_func, 1, [d], backend="cpu")
    assert d.numpy()[0] == 2.0 * math.pi


@wp.kernel
def expectations(a: wp.array(dtype=float), n: int):
    wp.expect_eq(n, 3)  # holds: silent
    wp.expect_eq(n, 4)
    wp.expect_neq(a[0], 1.0)
    wp.expect_neq(n, 4)  # holds: silent
    wp.expect_eq(wp.vec2(a[0], 2.0), wp.vec2(1.0, 2.5))
    wp.expect_near(a[0], 1.0000001)  # within the default 1e-6: silent
    wp.expect_near(a[0], 1.25, 0.125)
    wp.expect_near(wp.vec3(a[0]), wp.vec3(1.0, 1.0, 1.5), 0.25)
    print("went on")


EXPECTED = """\
Error, expect_eq() failed:
\t Expected: 4
\t Actual: 3
Error, expect_neq() failed:
\t Expected: 1
\t Actual: 1
Error, expect_eq() failed:
\t Expected: 1 2.5 
\t Actual: 1 2 
Error, expect_near() failed with tolerance 0.125
    Expected: 1.25
    Actual: 1
    Absolute difference: 0.25
Error, expect_near() failed with tolerance 0.25
    Expected: 1 1 1.5 
    Actual: 1 1 1 
    Max absolute difference: 0.5
went on
"""  # noqa: W291 - Warp's vector format ends with a space


@pytest.mark.parametrize("backend", ALL)
def test_expect_prints_warps_message_and_the_kernel_goes_on(backend, capfd):
    dev = _device(backend)
    a = wp.array(np.ones(1, np.float32), device=dev)
    wp.launch(expectations, 1, [a, 3], device=dev, backend=backend)
    wp.synchronize()
    assert capfd.readouterr().out == EXPECTED


@wp.kernel
def block_size(out: wp.array(dtype=int)):
    out[wp.tid()] = wp.block_dim()


@pytest.mark.parametrize("backend", BACKENDS)
def test_block_dim_is_one_off_the_gpu(backend):
    out = wp.zeros(4, dtype=int)
    wp.launch(block_size, 4, [out], backend=backend)
    assert out.numpy().tolist() == [1, 1, 1, 1]


@pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA GPU")
def test_block_dim_on_cuda_is_the_block_size_kdsl_launches_with():
    out = wp.zeros(300, dtype=int, device="cuda")
    wp.launch(block_size, 300, [out], device="cuda")
    assert set(out.numpy().tolist()) == {256}


@wp.kernel
def static_reversed(out: wp.array(dtype=int)):
    k = 0
    for i in reversed(range(wp.static(4))):
        out[k] = i
        k += 1
    for i in reversed(range(2, 9, 3)):
        out[k] = i
        k += 1
    breakpoint()
    wp.breakpoint()


@pytest.mark.parametrize("backend", BACKENDS)
def test_reversed_unrolled_and_constant_ranges_and_breakpoint(backend):
    out = wp.zeros(7, dtype=int)
    wp.launch(static_reversed, 1, [out], backend=backend)
    assert out.numpy().tolist() == [3, 2, 1, 0, 8, 5, 2]


@wp.kernel
def lower_bound_ints(arr: wp.array(dtype=wp.int64), q: wp.array(dtype=wp.int64),
                     out: wp.array(dtype=int)):  # fmt: skip
    i = wp.tid()
    out[i] = wp.lower_bound(arr, q[i])


@pytest.mark.parametrize("backend", BACKENDS)
def test_lower_bound_quirks_follow_warp(backend):
    # The first index >= value, but end - 1 when every element is smaller (as Warp).
    arr = wp.array(np.array([1, 3, 3, 7], np.int64))
    q = wp.array(np.array([0, 1, 2, 3, 7, 100], np.int64))
    out = wp.zeros(6, dtype=int)
    wp.launch(lower_bound_ints, 6, [arr, q, out], backend=backend)
    assert out.numpy().tolist() == [0, 0, 1, 1, 3, 3]


def _compile_error(src_fn, match: str, cls=KdslTypeError):
    with pytest.raises(cls, match=match) as info:
        wp.launch(src_fn, 1, [], backend="interp")
    assert __file__ in str(info.value)


def test_errors_are_located():
    @wp.kernel
    def bad_bits():
        wp.bit_and(1.5, 2)

    _compile_error(bad_bits, r"bit_and\(\) needs integers, not the literal 1.5")

    @wp.kernel
    def bad_invert():
        wp.invert(wp.vec3(1.0))

    _compile_error(bad_invert, r"invert\(\) needs integers")

    @wp.kernel
    def bad_cast_width():
        wp.cast(wp.float64(1.0), wp.int32)

    _compile_error(bad_cast_width, r"cast\(\) needs types of one width")

    @wp.kernel
    def bad_cast_type():
        wp.cast(1.0, wp.vec3)

    _compile_error(bad_cast_type, r"cast\(\) needs a scalar type")

    @wp.kernel
    def bad_reversed():
        x = reversed(3)

    _compile_error(bad_reversed, r"reversed\(\) can only wrap range", KdslSyntaxError)

    @wp.kernel
    def bad_reversed_arg():
        for i in reversed(3):  # noqa: B007
            pass

    _compile_error(bad_reversed_arg, r"must wrap range", KdslSyntaxError)

    @wp.kernel
    def bad_expect():
        wp.expect_eq(wp.vec3(1.0), wp.vec2(1.0))

    _compile_error(bad_expect, r"expect_eq\(\) needs two values of one type")

    @wp.kernel
    def bad_near():
        wp.expect_near(1, 2)

    _compile_error(bad_near, r"expect_near\(\) needs floats")

    @wp.kernel
    def bad_add():
        wp.add(wp.vec3(1.0), 1.0)

    _compile_error(bad_add, r"cannot add")
