"""warp-lang as a peer for tests that run the same kernels on Warp's CPU device."""

from types import ModuleType

import pytest


def import_warp_cpu() -> ModuleType:
    """The ``warp`` module, quiet; skips the calling test module where warp-lang is not
    installed (the ``bench`` extra) or cannot build CPU kernels (an install without
    ``warp-clang``, as carried to the GPU machine)."""
    warp = pytest.importorskip("warp")
    warp.config.quiet = True
    if not warp.is_cpu_available():
        pytest.skip("warp-lang here cannot build CPU kernels (no warp-clang)", allow_module_level=True)
    return warp
