"""IR types as LLVM types, for registers and for memory.

Registers: bool is ``i1``, integers ``iN`` (signedness lives in the IR type, not
here), floats ``half``/``float``/``double``. Vectors, quaternions, transforms,
matrices and structs have no register type of their own: they live as their
scalar parts (``composite.Parts``), so LLVM sees only scalar code and its loop
vectorizer can take loops that use them. Arrays are descriptors ``{ptr data, [ndim x i64] shape, [ndim x i64] strides}``
whose strides count scalar elements (not bytes) so LLVM sees unit strides.

Memory: a bool is one byte (NumPy's layout), everything else as in registers; the
components of a vector or matrix element are consecutive scalars (row-major).
"""

from __future__ import annotations

import math

from llvmlite import ir

from kdsl.errors import KdslCapabilityError
from kdsl.ir import types as T

PTR = ir.PointerType()
I1 = ir.IntType(1)
I8 = ir.IntType(8)
I32 = ir.IntType(32)
I64 = ir.IntType(64)
F32 = ir.FloatType()
VOID = ir.VoidType()


def _parse(spelling: str) -> ir.Type:
    """The llvmlite type of an LLVM scalar type spelling (``i32``, ``half``, ``double``)."""
    if spelling.startswith("i"):
        return ir.IntType(int(spelling[1:]))
    return {"half": ir.HalfType, "float": ir.FloatType, "double": ir.DoubleType}[spelling]()


#: The register type of each scalar, parsed from the scalar table's LLVM spellings.
_REGISTER: dict[T.ScalarType, ir.Type] = {t: _parse(t.llvm) for t in T.SCALARS.values()}


def scalar_type(t: T.ScalarType) -> ir.Type:
    """The register type of a scalar."""
    return _REGISTER[t]


def count(t: T.Type) -> int:
    """Number of scalars in a scalar, vector or matrix value."""
    return math.prod(T.value_shape(t))


def descriptor_type(ndim: int) -> ir.LiteralStructType:
    """The array descriptor struct of an ``ndim``-d array."""
    dims = ir.ArrayType(I64, ndim)
    return ir.LiteralStructType([PTR, dims, dims])


def llvm_type(t: T.Type) -> ir.Type:
    """The register type of a leaf IR type: scalar, array (descriptor) or handle.

    Vector, matrix and struct values are several registers: see ``composite.leaf_types``.
    """
    if isinstance(t, T.ScalarType):
        return scalar_type(t)
    if isinstance(t, T.ArrayType):
        return descriptor_type(t.ndim)
    if isinstance(t, T.HandleType):
        return I64
    raise KdslCapabilityError(f"the cpu backend cannot represent values of type {t}")


def memory_scalar(t: T.ScalarType) -> ir.Type:
    """The in-memory type of one scalar component (bool is a byte)."""
    return I8 if t.is_bool else scalar_type(t)
