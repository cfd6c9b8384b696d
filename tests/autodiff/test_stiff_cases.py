"""The stiff and extreme gradient cases: kdsl's gradients match float64 finite differences."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl
from kdsl.testing import stiff_cases

KERNELS = stiff_cases.build(kdsl)


@pytest.mark.parametrize("case", stiff_cases.CASES, ids=lambda c: c.kernel)
def test_gradient_matches_finite_differences(case):
    row = stiff_cases.evaluate(kdsl, KERNELS, case)
    assert row["verdict"] in ("ok", "ill-conditioned"), row
    assert np.all(np.isfinite(row["d_x0"])) and np.isfinite(row["d_k"])


def test_classify_reports_each_verdict():
    want = (np.array([2.0]), np.array([1.0, 3.0]))
    assert stiff_cases.classify(want, want, True) == "ok"
    assert stiff_cases.classify((np.array([2.5]), want[1]), want, True) == "wrong"
    assert stiff_cases.classify((np.array([np.nan]), want[1]), want, True) == "nan"
    assert stiff_cases.classify((np.array([9.0]), want[1]), want, False) == "ill-conditioned"
