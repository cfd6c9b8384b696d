"""bfloat16 on the host: conversions between float32 values and bfloat16 bits.

bfloat16 keeps float32's sign and 8-bit exponent and the top 7 bits of its mantissa, so
a bfloat16 is the upper half of a float32. ``to_bits`` rounds to nearest, ties to even
(as CUDA's ``__float2bfloat16_rn``, Warp and ``ml_dtypes`` do), and keeps a NaN a
(quiet) NaN; ``from_bits`` is exact. Kernels convert with the same rule
(``kdsl/frontend/bfloat16.py``), so host and device agree bit for bit.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def to_bits(x: Any) -> np.ndarray:
    """``x`` (numbers, converted to float32 first) as bfloat16 bits (uint16), rounded to
    nearest even; NaN stays NaN."""
    f = np.asarray(x, dtype=np.float32)
    b = f.view(np.uint32)
    rounded = b + np.uint32(0x7FFF) + ((b >> np.uint32(16)) & np.uint32(1))
    # A NaN whose payload sits in the low half would round into an infinity: set the
    # quiet bit instead of rounding.
    out = np.where(np.isnan(f), b | np.uint32(0x0040_0000), rounded)
    return (out >> np.uint32(16)).astype(np.uint16)


def from_bits(bits: Any) -> np.ndarray:
    """bfloat16 ``bits`` (uint16) as float32 values (exact)."""
    b = np.asarray(bits, dtype=np.uint16).astype(np.uint32) << np.uint32(16)
    return b.view(np.float32)


def numpy_dtype() -> np.dtype | None:
    """NumPy's bfloat16 dtype from ``ml_dtypes`` when that package is installed, else None."""
    try:
        import ml_dtypes
    except ImportError:
        return None
    return np.dtype(ml_dtypes.bfloat16)
