"""Dtype mapping between kdsl and other frameworks, derived from kdsl's one dtype table.

No second table lives here: a framework dtype is matched to a kdsl scalar through
its NumPy name (``torch.float32`` -> ``"float32"`` -> ``kdsl.ir.types`` ``f32``),
and back through the scalar table's name for that framework (``ScalarType.torch``,
``.paddle``, ``.jax``). A dtype kdsl has no scalar for (complex, strings) is an
``InteropTypeError``, and so is bfloat16: kdsl's is a storage type, and NumPy's DLPack
import (which kdsl's zero-copy paths use) has no bfloat16; such data is passed as its
16-bit patterns (``kdsl.array(bits, dtype=kdsl.bfloat16)`` takes uint16 data as bits).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from kdsl.errors import KdslError, KdslTypeError
from kdsl.ir import types as T
from kdsl.runtime.dtypes import resolve_dtype
from kdsl.types import class_of


class InteropTypeError(KdslTypeError, TypeError):
    """A dtype with no counterpart on the other side (also a ``TypeError``, as Warp raises)."""


class InteropDeviceError(KdslError, RuntimeError):
    """A device with no counterpart on the other side (also a ``RuntimeError``, as Warp raises)."""


_KNOWN = ", ".join(class_of(t).__name__ for t in T.SCALARS.values() if t is not T.BF16)
#: Why a bfloat16 tensor does not cross zero-copy (``{what}`` names it), and what to do.
BF16_HINT = (
    "{what} has no kdsl equivalent for zero-copy interop: kdsl's bfloat16 arrays hold 16-bit "
    "patterns; pass them as uint16 (torch: t.view(torch.uint16), then "
    "kdsl.array(bits, dtype=kdsl.bfloat16)) or convert to float32 first"
)


def scalar_from_name(name: str, what: str) -> T.ScalarType:
    """The kdsl scalar whose NumPy name is ``name`` (``"float32"``); ``what`` names the source."""
    if name == "bfloat16":
        raise InteropTypeError(BF16_HINT.format(what=what))
    try:
        return T.scalar_from_numpy(np.dtype(name))
    except (TypeError, KeyError, ValueError):
        raise InteropTypeError(
            f"{what} has no kdsl equivalent (kdsl scalars: {_KNOWN}); convert it first, "
            f"e.g. to float32"
        ) from None


def scalar_from_numpy_dtype(dtype: np.dtype, what: str) -> T.ScalarType:
    """The kdsl scalar of a NumPy dtype (ml_dtypes' bfloat16 and complex are errors)."""
    if np.dtype(dtype).name == "bfloat16":
        raise InteropTypeError(BF16_HINT.format(what=what))
    try:
        return T.scalar_from_numpy(dtype)
    except (TypeError, KeyError, ValueError):
        raise InteropTypeError(
            f"{what} has no kdsl equivalent (kdsl scalars: {_KNOWN}); convert it first, "
            f"e.g. to float32"
        ) from None


def framework_name(prefixed: Any) -> str:
    """``"float32"`` from ``torch.float32`` / ``paddle.float32`` (their ``str`` is prefixed)."""
    return str(prefixed).rpartition(".")[2]


def kdsl_scalar(dtype: Any, target: str) -> T.ScalarType:
    """The scalar IR type of a kdsl dtype; vectors and matrices are errors naming ``target``."""
    try:
        t = resolve_dtype(dtype)
    except KdslError as e:
        raise InteropTypeError(
            f"cannot convert {dtype!r} to a {target} dtype: {e.message}"
        ) from None
    if not isinstance(t, T.ScalarType):
        et = T.elem_type(t)
        dims = ", ".join(map(str, T.value_shape(t)))
        raise InteropTypeError(
            f"{class_of(t).__name__} has no {target} dtype: an array of it converts to a "
            f"tensor of {et.np_dtype.name} with extra inner dims (..., {dims})"
        )
    return t


def public_scalar(t: T.ScalarType) -> type:
    """The public class (``kdsl.float32``) of a scalar IR type."""
    return class_of(t)
