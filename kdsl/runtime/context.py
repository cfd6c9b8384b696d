"""Process-wide runtime setup (``kdsl.context`` in Warp's spelling)."""

from __future__ import annotations

from kdsl.runtime.device import Device, get_device, is_cuda_available

_initialized = False


def init() -> None:
    """Initialize the runtime. Optional, idempotent and cheap: kdsl sets up lazily."""
    global _initialized
    _initialized = True


def is_initialized() -> bool:
    """True once ``init`` ran."""
    return _initialized


__all__ = ["Device", "get_device", "init", "is_cuda_available", "is_initialized"]
