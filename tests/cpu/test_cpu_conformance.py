"""The shared conformance suite (kdsl.testing) on the cpu backend."""

from __future__ import annotations

import pytest

from kdsl.testing.cases import all_cases
from kdsl.testing.conformance import check_case

CASES = all_cases()


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_conformance(case, cpu_backend) -> None:
    lacking = [c for c in case.requires if c not in cpu_backend.capabilities]
    if lacking:
        pytest.skip(f"the cpu backend lacks {', '.join(lacking)}")
    check_case(case, "cpu")
