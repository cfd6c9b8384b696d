"""Defects the differential fuzzer (kdsl.testing.fuzz) found, each pinned by a test
named after what it exercises (docs/testing.md, "Differential fuzzing")."""

import numpy as np
import pytest

import kdsl as wp

BACKENDS = ["interp", "cpu"]


@wp.kernel
def nested_loops_with_return(xs: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    total = 0.0
    for a in range(3):
        for b in range(4):
            if xs[i] * float(a * 4 + b) > 5.0:
                out[i] = total
                return
            total += float(b)
        total += 10.0
    out[i] = total


@wp.kernel
def nested_dynamic_loops_with_break(
    xs: wp.array(dtype=float), ns: wp.array(dtype=int), out: wp.array(dtype=float)
):
    i = wp.tid()
    total = 0.0
    for a in range(ns[i]):
        for b in range(ns[i]):
            if float(a + b) > xs[i]:
                break
            total += float(a * 10 + b)
        if total > 40.0:
            break
    out[i] = total


def _nested_loops_reference(x: float) -> float:
    total = 0.0
    for a in range(3):
        for b in range(4):
            if x * (a * 4 + b) > 5.0:
                return total
            total += b
        total += 10.0
    return total


def _nested_dynamic_reference(x: float, n: int) -> float:
    total = 0.0
    for a in range(n):
        for b in range(n):
            if a + b > x:
                break
            total += a * 10 + b
        if total > 40.0:
            break
    return total


@pytest.mark.parametrize("backend", BACKENDS)
def test_nested_loops_that_return_keep_the_outer_counter(backend):
    # Both loops exit early, so both lower to scf.while with a counter each: the inner
    # loop used to rebind and drop the outer one's ("internal: loop variable $iv lost").
    xs = np.array([0.0, 0.3, 0.6, 1.0, 2.5, 6.0], dtype=np.float32)
    out = wp.zeros(len(xs), dtype=float)
    wp.launch(nested_loops_with_return, dim=len(xs), inputs=[wp.array(xs), out], backend=backend)
    np.testing.assert_allclose(out.numpy(), [_nested_loops_reference(float(x)) for x in xs])


@pytest.mark.parametrize("backend", BACKENDS)
def test_nested_dynamic_loops_that_break_keep_the_outer_counter(backend):
    xs = np.array([0.5, 2.0, 3.5, 9.0, 1.0, 4.0], dtype=np.float32)
    ns = np.array([3, 4, 2, 5, 0, 6], dtype=np.int32)
    out = wp.zeros(len(xs), dtype=float)
    args = [wp.array(xs), wp.array(ns), out]
    wp.launch(nested_dynamic_loops_with_break, dim=len(xs), inputs=args, backend=backend)
    want = [_nested_dynamic_reference(float(x), int(n)) for x, n in zip(xs, ns)]
    np.testing.assert_allclose(out.numpy(), want)


def test_launch_with_an_unknown_backend_names_the_launch_line():
    # Was an unlocated BackendRegistryError from the registry.
    out = wp.zeros(2, dtype=float)
    with pytest.raises(wp.errors.KdslLaunchError) as info:
        wp.launch(nested_loops_with_return, dim=2, inputs=[out, out], backend="no_such_backend")
    err = info.value
    assert err.loc is not None and err.loc.file == __file__ and err.loc.line > 0
    assert "launch(backend='no_such_backend'): no kdsl backend is named 'no_such_backend'" in str(
        err
    )
