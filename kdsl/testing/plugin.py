"""The pytest plugin of the conformance suite: adds ``--kdsl-backend``.

Load it with ``-p kdsl.testing.plugin``::

    pytest --pyargs kdsl.testing -p kdsl.testing.plugin --kdsl-backend=interp

Without the option, the suite runs on every registered backend.
"""

from __future__ import annotations

import pytest


def pytest_addoption(parser: pytest.Parser) -> None:
    """Register ``--kdsl-backend NAME`` (repeatable)."""
    group = parser.getgroup("kdsl", "kdsl conformance suite")
    group.addoption(
        "--kdsl-backend",
        action="append",
        dest="kdsl_backend",
        default=None,
        metavar="NAME",
        help="run the conformance suite on this backend (repeat for several; default: all)",
    )
