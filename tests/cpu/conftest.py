"""Fixtures: the cpu backend registered for the duration of a test module, and launches
forced inline or onto the pool."""

from __future__ import annotations

import pytest

from kdsl.backends import registry
from kdsl.backends.cpu import pool


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


@pytest.fixture(params=["inline", "pool"])
def split(request):
    """Launches run inline (one range) or split over the pool's threads (a range each)."""
    old = pool.min_parallel, pool.adaptive
    pool.adaptive = False
    pool.min_parallel = 1 << 30 if request.param == "inline" else 1
    try:
        yield request.param
    finally:
        pool.min_parallel, pool.adaptive = old
