"""Fixtures: the cpu backend registered for the duration of a test module."""

from __future__ import annotations

import pytest

from kdsl.backends import registry


@pytest.fixture(scope="module")
def cpu_backend():
    """The cpu backend, registered as "cpu" (and unregistered after, if we registered it)."""
    from kdsl.backends.cpu import BACKEND

    if registry.is_registered("cpu"):  # the entry point already provides it
        yield registry.get_backend("cpu")
        return
    registry.register_backend(BACKEND)
    try:
        yield BACKEND
    finally:
        registry.unregister_backend("cpu")
