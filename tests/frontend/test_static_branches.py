"""Compile-time conditions drop the branch not taken before it is lowered, as Warp does:
``wp.static(...)``, closure constants and typed constants in ``if``/``elif``/``else``,
conditional expressions, ``and``/``or`` and ``not``, at a kernel's top level, in for and
while loops (bodies and conditions) and in ``@func`` bodies. The factories live in
``static_branch_cases.py``; Warp's results there are checked side by side below."""

import numpy as np
import pytest

import kdsl as wp
from tests.device_targets import TARGETS
from tests.frontend import static_branch_cases as cases
from tests.frontend.located_errors import expect_error_at_marker
from tests.warp_peer import import_warp_cpu

RUNS = {**cases.RESULTS, **cases.KDSL_ONLY}


def _launch(mod, kernel, device, **launch_options):
    a = mod.array(np.ones(2, dtype=np.float32), dtype=mod.float32, device=device)
    n = mod.array(np.array([3, 3], dtype=np.int32), dtype=mod.int32, device=device)
    mod.launch(kernel, dim=2, inputs=[a, n], device=device, **launch_options)
    return a.numpy(), n.numpy()


def _id(run) -> str:
    factory, flag = run
    return f"{factory.__name__}-{flag}"


@pytest.mark.parametrize(("device", "backend"), TARGETS)
@pytest.mark.parametrize("run", list(RUNS), ids=_id)
def test_dead_branch_is_not_lowered(run, device, backend):
    factory, flag = run
    kernel = factory(wp, flag, {})
    a, n = _launch(wp, kernel, device, **({"backend": backend} if backend else {}))
    want_a, want_n = RUNS[run]
    np.testing.assert_array_equal(a, [want_a] * 2)
    np.testing.assert_array_equal(n, [want_n] * 2)


@pytest.mark.parametrize("run", list(cases.LIVE_ERRORS), ids=_id)
def test_live_branch_errors_stay_located(run):
    factory, flag = run
    expect_error_at_marker(factory(wp, flag, {}), cases.LIVE_ERRORS[run])


def test_the_taken_branch_alone_is_in_the_ir(build_text, check_ir):
    text = build_text(cases.while_condition(wp, True, {}))
    check_ir(
        text,
        """
        CHECK: scf.while
        CHECK-NOT: f64
        CHECK-NOT: scf.if
        CHECK: scf.condition
        """,
    )


@pytest.mark.parametrize("run", list(cases.RESULTS), ids=_id)
def test_side_by_side_with_warp(run):
    warp = import_warp_cpu()
    factory, flag = run
    got = _launch(warp, factory(warp, flag, {"module": "unique"}), "cpu")
    want = _launch(wp, factory(wp, flag, {}), "cpu")
    np.testing.assert_array_equal(got[0], want[0])
    np.testing.assert_array_equal(got[1], want[1])
    assert (got[0][0], got[1][0]) == cases.RESULTS[run]


@pytest.mark.parametrize("run", list(cases.LIVE_ERRORS)[:1], ids=_id)
def test_warp_rejects_the_live_errors_too(run):
    warp = import_warp_cpu()
    factory, flag = run
    with pytest.raises(Exception, match="Input types must be the same"):
        _launch(warp, factory(warp, flag, {"module": "unique"}), "cpu")


TYPED_ONE = wp.constant(np.int32(1))


@wp.kernel
def k_global_typed_constant(a: wp.array(dtype=float)):
    i = wp.tid()
    if TYPED_ONE:
        a[i] = a[i] + 1.0
    elif not TYPED_ONE:
        a[i] = a[i] + wp.float64(1.0)
    a[i] = a[i] + (2.0 if TYPED_ONE and wp.static(True) else wp.float64(3.0))


def make_axpy(dtype):
    """The kernel factory of docs/language.md ("Compile-time conditions")."""

    @wp.kernel
    def axpy(a: wp.array(dtype=dtype), x: wp.array(dtype=dtype)):
        i = wp.tid()
        if wp.static(dtype == wp.float64):
            a[i] = a[i] + wp.float64(2.0) * x[i]  # never checked for float32
        else:
            a[i] = a[i] + dtype(2.0) * x[i]

    return axpy


@pytest.mark.parametrize(("device", "backend"), TARGETS)
def test_typed_global_constant_condition(device, backend):
    a = wp.ones(2, dtype=float, device=device)
    wp.launch(k_global_typed_constant, dim=2, inputs=[a], device=device, backend=backend)
    np.testing.assert_array_equal(a.numpy(), [4.0, 4.0])


@pytest.mark.parametrize(("device", "backend"), TARGETS)
@pytest.mark.parametrize(
    ("dtype", "np_dtype"), [(wp.float32, np.float32), (wp.float64, np.float64)]
)
def test_documented_factory(dtype, np_dtype, device, backend):
    a = wp.array(np.ones(3, dtype=np_dtype), dtype=dtype, device=device)
    x = wp.array(np.full(3, 0.5, dtype=np_dtype), dtype=dtype, device=device)
    wp.launch(make_axpy(dtype), dim=3, inputs=[a, x], device=device, backend=backend)
    np.testing.assert_array_equal(a.numpy(), [2.0, 2.0, 2.0])


@wp.kernel
def k_static_false_while(a: wp.array(dtype=float)):
    i = wp.tid()
    while wp.static(False):
        a[i] = a[i] + wp.float64(1.0)  # <-


def test_while_with_a_false_static_condition_is_still_checked():
    # As in Warp 1.19: only branches are dropped, a loop's body is always lowered.
    expect_error_at_marker(k_static_false_while, "cannot add f32 and f64")
