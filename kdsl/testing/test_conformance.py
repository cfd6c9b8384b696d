"""The conformance suite as pytest tests: every case on every selected backend and device.

Cases a backend cannot run (a capability it lacks) are skipped with the reason.
"""

from __future__ import annotations

import pytest

from kdsl.testing.case import Case
from kdsl.testing.cases import all_cases
from kdsl.testing.conformance import Target, check_case, missing_capabilities, targets


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    """Parametrize ``case`` x ``target``; ``--kdsl-backend`` picks the backends."""
    if "case" not in metafunc.fixturenames or "target" not in metafunc.fixturenames:
        return
    chosen = metafunc.config.getoption("kdsl_backend", default=None)
    params = [pytest.param(case, target, id=f"{case.name}-{target}")
              for target in targets(chosen) for case in all_cases()]  # fmt: skip
    metafunc.parametrize(("case", "target"), params)


def test_case(case: Case, target: Target) -> None:
    """The backend's outputs match the case's NumPy reference."""
    lacking = missing_capabilities(case, target)
    if lacking:
        pytest.skip(f"backend {target.backend} lacks {', '.join(lacking)}")
    check_case(case, target)
