"""IR types: immutable, hashable, and printed in the text form.

This module is the one dtype table of kdsl. Every scalar type is listed once in
``SCALARS`` with its NumPy dtype; the public ``kdsl.float32``-style names, the
runtime's array dtypes and every backend read their facts from here.

Text forms::

    bool  i8 i16 i32 i64  u8 u16 u32 u64  f16 f32 f64
    vec<3, f32>   mat<3, 3, f32>   quat<f32>   transform<f32>
    array<vec<3, f32>, 2>   struct<Particle>   handle<mesh>
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np


class Type:
    """Base class of every IR type. Subclasses are frozen dataclasses."""

    def __str__(self) -> str:  # pragma: no cover - every subclass overrides
        raise NotImplementedError

    @property
    def is_scalar(self) -> bool:
        return isinstance(self, ScalarType)

    @property
    def is_value(self) -> bool:
        """True for types whose values live in registers (not arrays or handles)."""
        return isinstance(self, ScalarType | VectorType | MatrixType | StructType)


@dataclass(frozen=True)
class ScalarType(Type):
    """A scalar: ``kind`` is one of bool, int, uint, float; ``bits`` its width."""

    kind: str
    bits: int

    @property
    def name(self) -> str:
        if self.kind == "bool":
            return "bool"
        return {"int": "i", "uint": "u", "float": "f"}[self.kind] + str(self.bits)

    @property
    def is_float(self) -> bool:
        return self.kind == "float"

    @property
    def is_int(self) -> bool:
        """True for signed and unsigned integers (not bool)."""
        return self.kind in ("int", "uint")

    @property
    def is_signed(self) -> bool:
        return self.kind in ("int", "float")

    @property
    def is_bool(self) -> bool:
        return self.kind == "bool"

    @property
    def np_dtype(self) -> np.dtype:
        return np.dtype(_NP_NAMES[self.name])

    def __str__(self) -> str:
        return self.name


BOOL = ScalarType("bool", 8)
I8, I16, I32, I64 = (ScalarType("int", b) for b in (8, 16, 32, 64))
U8, U16, U32, U64 = (ScalarType("uint", b) for b in (8, 16, 32, 64))
F16, F32, F64 = (ScalarType("float", b) for b in (16, 32, 64))

_NP_NAMES = {
    "bool": "bool",
    "i8": "int8", "i16": "int16", "i32": "int32", "i64": "int64",
    "u8": "uint8", "u16": "uint16", "u32": "uint32", "u64": "uint64",
    "f16": "float16", "f32": "float32", "f64": "float64",
}  # fmt: skip

#: Every scalar type by its text name. The single dtype table.
SCALARS: dict[str, ScalarType] = {
    t.name: t for t in (BOOL, I8, I16, I32, I64, U8, U16, U32, U64, F16, F32, F64)
}


_BY_NP_NAME: dict[str, ScalarType] = {_NP_NAMES[t.name]: t for t in SCALARS.values()}
_BY_NP: dict[object, ScalarType] = {
    key: t for t in SCALARS.values() for key in (t.np_dtype, t.np_dtype.type)
}

#: Each scalar's ``struct`` module code (standard sizes, used with a ``<`` prefix),
#: for backends that pack launch arguments.
_STRUCT_CODES = {
    "bool": "?", "i8": "b", "i16": "h", "i32": "i", "i64": "q",
    "u8": "B", "u16": "H", "u32": "I", "u64": "Q", "f16": "e", "f32": "f", "f64": "d",
}  # fmt: skip


def struct_code(t: ScalarType) -> str:
    """The ``struct`` format code of scalar ``t`` (standard size, for ``<`` formats)."""
    return _STRUCT_CODES[t.name]


def scalar_from_numpy(dtype: np.dtype | type) -> ScalarType:
    """The scalar type for a NumPy dtype; raises KeyError for ones kdsl lacks."""
    # Interop calls this per array: a dict hit on the dtype object itself first.
    t = _BY_NP.get(dtype)
    if t is None:
        t = _BY_NP_NAME.get(np.dtype(dtype).name)
        if t is None:
            raise KeyError(np.dtype(dtype).name)
    return t


@dataclass(frozen=True)
class VectorType(Type):
    """A fixed-length vector of scalars, e.g. ``vec<3, f32>``."""

    length: int
    elem: ScalarType

    def __str__(self) -> str:
        return f"vec<{self.length}, {self.elem}>"

    @property
    def shape(self) -> tuple[int, ...]:
        return (self.length,)


@dataclass(frozen=True)
class MatrixType(Type):
    """A row-major ``rows x cols`` matrix of scalars, e.g. ``mat<3, 3, f32>``."""

    rows: int
    cols: int
    elem: ScalarType

    def __str__(self) -> str:
        return f"mat<{self.rows}, {self.cols}, {self.elem}>"

    @property
    def shape(self) -> tuple[int, ...]:
        return (self.rows, self.cols)

    @property
    def row_type(self) -> VectorType:
        return VectorType(self.cols, self.elem)


@dataclass(frozen=True, init=False)
class QuatType(VectorType):
    """A quaternion (x, y, z, w): stored like a 4-vector, typed apart from one."""

    def __init__(self, elem: ScalarType) -> None:
        object.__setattr__(self, "length", 4)
        object.__setattr__(self, "elem", elem)

    def __str__(self) -> str:
        return f"quat<{self.elem}>"


@dataclass(frozen=True, init=False)
class TransformType(VectorType):
    """A rigid transform (p.x, p.y, p.z, q.x, q.y, q.z, q.w): 7 scalars."""

    def __init__(self, elem: ScalarType) -> None:
        object.__setattr__(self, "length", 7)
        object.__setattr__(self, "elem", elem)

    def __str__(self) -> str:
        return f"transform<{self.elem}>"


@dataclass(frozen=True)
class StructType(Type):
    """A named record. Equality is by name and fields, so two definitions agree."""

    name: str
    fields: tuple[tuple[str, Type], ...] = field(default=())

    def __str__(self) -> str:
        return f"struct<{self.name}>"

    def field_type(self, name: str) -> Type:
        for fname, ftype in self.fields:
            if fname == name:
                return ftype
        raise KeyError(name)

    def field_index(self, name: str) -> int:
        for i, (fname, _) in enumerate(self.fields):
            if fname == name:
                return i
        raise KeyError(name)

    def definition(self) -> str:
        """The module-level text form: ``struct Particle {x: vec<3, f32>, m: f32}``."""
        body = ", ".join(f"{n}: {t}" for n, t in self.fields)
        return f"struct {self.name} {{{body}}}"


@dataclass(frozen=True)
class ArrayType(Type):
    """An array descriptor (pointer, shape, strides) of ``ndim`` dimensions."""

    dtype: Type
    ndim: int

    def __str__(self) -> str:
        return f"array<{self.dtype}, {self.ndim}>"


@dataclass(frozen=True)
class HandleType(Type):
    """An opaque 64-bit handle to a runtime object (mesh, hash_grid, volume, bvh)."""

    kind: str
    KINDS: ClassVar[tuple[str, ...]] = ("mesh", "hash_grid", "volume", "bvh")

    def __str__(self) -> str:
        return f"handle<{self.kind}>"


def elem_type(t: Type) -> ScalarType:
    """The scalar element type of a scalar, vector or matrix type."""
    if isinstance(t, ScalarType):
        return t
    if isinstance(t, VectorType | MatrixType):
        return t.elem
    raise TypeError(f"{t} has no scalar element type")


def with_elem(t: Type, elem: ScalarType) -> Type:
    """``t`` with its scalar element type replaced (used by casts and comparisons)."""
    if isinstance(t, ScalarType):
        return elem
    if isinstance(t, QuatType):
        return QuatType(elem)
    if isinstance(t, TransformType):
        return TransformType(elem)
    if isinstance(t, VectorType):
        return VectorType(t.length, elem)
    if isinstance(t, MatrixType):
        return MatrixType(t.rows, t.cols, elem)
    raise TypeError(f"{t} has no scalar element type")


def value_shape(t: Type) -> tuple[int, ...]:
    """NumPy shape of one value of ``t`` (``()`` for scalars)."""
    if isinstance(t, ScalarType):
        return ()
    if isinstance(t, VectorType | MatrixType):
        return t.shape
    raise TypeError(f"{t} has no fixed shape")


def storage_dtype(t: Type) -> np.dtype:
    """The NumPy dtype of one value of ``t`` in memory (an array element).

    Structs use C's natural layout: each field at the next multiple of its own
    alignment, the struct aligned to its widest field and padded to a multiple
    of that. The cpu backend's field offsets, the CUDA C structs and NumPy's
    structured arrays all read their layout from here, so they agree. Raises
    ``TypeError`` for types with no memory layout (arrays, handles, and structs
    holding them).
    """
    if isinstance(t, ScalarType):
        return t.np_dtype
    if isinstance(t, VectorType | MatrixType):
        return np.dtype((t.elem.np_dtype, t.shape))
    if isinstance(t, StructType):
        names, formats, offsets, off, align = [], [], [], 0, 1
        for name, ft in t.fields:
            fd = storage_dtype(ft)
            a = fd.alignment
            off = (off + a - 1) // a * a
            names.append(name)
            formats.append(fd)
            offsets.append(off)
            off += fd.itemsize
            align = max(align, a)
        size = (off + align - 1) // align * align
        spec = {"names": names, "formats": formats, "offsets": offsets, "itemsize": size}
        return np.dtype(spec, align=True)
    raise TypeError(f"values of {t} cannot be stored in an array")
