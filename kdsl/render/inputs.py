"""What the renderers accept: points, indices, colors, vectors, quaternions, as NumPy.

Warp's renderers take kdsl/Warp arrays, NumPy arrays, lists and the vector, quaternion
and transform values alike; each helper here turns one of those into a float64 (or
int) NumPy array of a checked shape, or raises a ``KdslTypeError`` that names the
argument and points at the user's call (the first frame outside ``kdsl.render``).
"""

from __future__ import annotations

import math
import os
import sys
from typing import Any

import numpy as np

from kdsl.errors import KdslError, KdslTypeError, source_line
from kdsl.ir import Loc

_HERE = os.path.dirname(os.path.abspath(__file__))


class RenderDependencyError(KdslError, ImportError):
    """A renderer needs an optional package that is not installed (an ``ImportError`` too)."""


def user_loc() -> Loc | None:
    """The line of the first caller outside ``kdsl.render`` (for error messages)."""
    frame = sys._getframe(1)
    while frame is not None and os.path.dirname(os.path.abspath(frame.f_code.co_filename)) == _HERE:
        frame = frame.f_back
    if frame is None:
        return None
    file, line = frame.f_code.co_filename, frame.f_lineno
    text = source_line(file, line)
    if text is None:
        return Loc(file, line, 1, line, 1)
    col = len(text) - len(text.lstrip()) + 1
    return Loc(file, line, col, line, len(text.rstrip()) + 1)


def _numeric(value: Any, what: str) -> np.ndarray:
    """``value`` as a NumPy array of numbers (kdsl/Warp arrays and values convert)."""
    if hasattr(value, "numpy") and callable(value.numpy):
        value = value.numpy()  # a kdsl or Warp array, wherever it lives
    try:
        out = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise KdslTypeError(
            f"{what} must be numbers (an array, a sequence or a vector value), "
            f"got {type(value).__name__}", user_loc(),
        ) from None  # fmt: skip
    return out


def vector(value: Any, n: int, what: str) -> np.ndarray:
    """A length-``n`` float vector (a tuple, list, NumPy array or a kdsl/Warp vector value)."""
    out = _numeric(value, what).reshape(-1) if value is not None else None
    if out is None or out.shape != (n,):
        got = "None" if out is None else f"{out.size} values"
        raise KdslTypeError(f"{what} must have {n} components, got {got}", user_loc())
    return out


def points(value: Any, what: str = "points") -> np.ndarray:
    """An ``(n, 3)`` float array: an array of vec3, an ``(n, 3)`` array, a list of 3-vectors."""
    out = _numeric(value, what)
    if out.size == 0:
        return out.reshape(0, 3)
    if out.ndim != 2 or out.shape[1] != 3:
        raise KdslTypeError(
            f"{what} must be n 3-vectors (shape (n, 3) or an array of vec3), got shape "
            f"{out.shape}", user_loc(),
        )  # fmt: skip
    return out


def indices(value: Any, group: int, count: int, what: str = "indices") -> np.ndarray:
    """Integer indices as rows of ``group`` (flat or 2-d), each below ``count``."""
    raw = _numeric(value, what)
    if raw.size % group:
        raise KdslTypeError(
            f"{what} must hold a multiple of {group} entries, got {raw.size}", user_loc()
        )
    out = raw.astype(np.int64).reshape(-1, group)
    if not np.array_equal(out.reshape(-1), raw.reshape(-1)):
        raise KdslTypeError(f"{what} must be integers", user_loc())
    if out.size and (out.min() < 0 or out.max() >= count):
        raise KdslTypeError(
            f"{what} must lie in [0, {count}) (the number of points), got "
            f"{int(out.min())}..{int(out.max())}", user_loc(),
        )  # fmt: skip
    return out


def colors(value: Any, count: int, what: str = "colors") -> np.ndarray | None:
    """None, one RGB color as shape ``(3,)``, or one per point as ``(count, 3)``."""
    if value is None:
        return None
    out = _numeric(value, what)
    if out.shape == (3,) or out.shape == (count, 3):
        return out
    raise KdslTypeError(
        f"{what} must be one RGB color (3 numbers) or one per point ({count}, 3), got "
        f"shape {out.shape}", user_loc(),
    )  # fmt: skip


def radii(value: Any, count: int, what: str = "radius") -> np.ndarray:
    """A radius per point (``count`` values) from one number or ``count`` numbers."""
    out = _numeric(value, what)
    if out.ndim == 0:
        return np.full(count, float(out))
    if out.shape == (count,):
        return out
    raise KdslTypeError(
        f"{what} must be one number or one per point ({count}), got shape {out.shape}",
        user_loc(),
    )


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate the rows of ``v`` by the unit quaternion ``q = (x, y, z, w)``."""
    u, w = q[:3], q[3]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The shortest unit quaternion ``(x, y, z, w)`` that turns direction ``a`` into ``b``."""
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    c = float(np.dot(a, b))
    if c < -1.0 + 1e-12:  # opposite: half a turn about any axis normal to a
        axis = np.cross(a, [1.0, 0.0, 0.0])
        if np.linalg.norm(axis) < 1e-6:
            axis = np.cross(a, [0.0, 1.0, 0.0])
        axis /= np.linalg.norm(axis)
        return np.array([*axis, 0.0])
    q = np.array([*np.cross(a, b), 1.0 + c])
    return q / math.sqrt(float(np.dot(q, q)))
