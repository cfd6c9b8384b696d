"""``transform_expand``: Warp's Python-scope helper from a flat 7-element sequence."""

from __future__ import annotations

from typing import Any

import numpy as np

from kdsl.errors import KdslTypeError
from kdsl.types import quatf, transformf, vec3f


def transform_expand(t: Any) -> transformf:
    """A ``transformf`` from ``(px, py, pz, qx, qy, qz, qw)``: position, then quaternion.

    Any sequence or array of 7 numbers works (a ``transformf`` itself included).
    """
    try:
        values = np.asarray(t, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise KdslTypeError(f"transform_expand takes 7 numbers, not {t!r}") from None
    if values.size != 7:
        raise KdslTypeError(f"transform_expand takes 7 numbers (position, quaternion), "
                            f"got {values.size}")  # fmt: skip
    return transformf(vec3f(*values[:3]), quatf(*values[3:]))
