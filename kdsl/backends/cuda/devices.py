"""The CUDA devices CuPy sees, counted once; imports CuPy only when first asked."""

from __future__ import annotations

_count: int | None = None


def device_count() -> int:
    """Number of CUDA devices CuPy sees (0 without CuPy or a driver). Cached."""
    global _count
    if _count is None:
        try:
            import cupy

            _count = int(cupy.cuda.runtime.getDeviceCount())
        except Exception:  # no cupy, no driver, no device: all mean "no CUDA"
            _count = 0
    return _count
