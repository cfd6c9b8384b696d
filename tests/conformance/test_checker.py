"""The conformance machinery itself: it must catch wrong results, and skip fairly."""

import numpy as np
import pytest

from kdsl.testing import Case, Target, check_case
from kdsl.testing.cases import GROUPS, all_cases
from kdsl.testing.cases.programs import PROGRAMS
from kdsl.testing.conformance import compare, missing_capabilities, targets

SAXPY = PROGRAMS["saxpy"]


def _saxpy_case(reference, **kw) -> Case:
    def make(rng):
        return {"x": np.arange(8, dtype=np.float32), "y": np.ones(8, np.float32), "a": 2.0}

    return Case("saxpy_check", SAXPY, 8, make, reference, ("y",), **kw)


def test_suite_is_large_and_unique():
    cases = all_cases()
    assert len(cases) >= 60
    assert len({c.name for c in cases}) == len(cases)
    assert len(GROUPS) >= 8


def test_correct_reference_passes():
    check_case(_saxpy_case(lambda ins: {"y": 2.0 * ins["x"] + ins["y"]}), "interp")


def test_wrong_reference_fails_with_the_index():
    case = _saxpy_case(lambda ins: {"y": 2.0 * ins["x"] + ins["y"] + (ins["x"] == 5)})
    with pytest.raises(AssertionError, match=r"1 of 8 elements; first at index \(5,\)"):
        check_case(case, "interp")


def test_compare_tolerances_and_nan():
    case = _saxpy_case(lambda ins: {})
    compare(case, "y", np.array([1.0, np.nan], np.float32), [1.0 + 1e-7, np.nan])
    with pytest.raises(AssertionError, match="rtol"):
        compare(case, "y", np.array([1.0], np.float32), [1.001])
    with pytest.raises(AssertionError, match="exact"):
        compare(case, "y", np.array([3], np.int32), [4])
    with pytest.raises(AssertionError, match="shape"):
        compare(case, "y", np.zeros(3, np.float32), np.zeros(4))
    with pytest.raises(AssertionError):
        compare(case, "y", np.array([np.nan], np.float32), [1.0])


def test_capability_gating():
    case = _saxpy_case(lambda ins: {}, requires=("fp64", "warp-drive"))
    target = Target("x", "cpu", frozenset({"fp64"}))
    assert missing_capabilities(case, target) == ["warp-drive"]


def test_unknown_backend_is_named():
    with pytest.raises(KeyError, match="no backend named 'nope'"):
        targets(["nope"])


def test_ulp_tolerance():
    from kdsl.testing.conformance import ulp_distance

    one = np.float32(1.0)
    got = np.array([one, np.nextafter(one, np.float32(2)), np.nan, np.inf], np.float32)
    want = np.array([1.0, 1.0, np.nan, np.inf])
    np.testing.assert_array_equal(ulp_distance(got, want), [0.0, 1.0, 0.0, 0.0])
    assert ulp_distance(np.array([np.nan], np.float32), np.array([1.0]))[0] == np.inf
    case = _saxpy_case(lambda ins: {}, ulps=2)
    compare(case, "y", np.array([np.nextafter(one, np.float32(2))], np.float32), [1.0])
    with pytest.raises(AssertionError, match="ulps, 2 allowed"):
        compare(case, "y", np.array([np.float32(1.0) + np.float32(1e-6)], np.float32), [1.0])
