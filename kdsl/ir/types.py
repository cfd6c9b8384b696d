"""IR types: immutable, hashable, and printed in the text form.

This module is the one dtype table of kdsl. Every scalar type is one row of the
scalar table below, and its ``ScalarType`` carries all its facts as fields: the IR
name, NumPy dtype, ``struct`` code, CUDA C and LLVM spellings, Warp's vector suffix,
and the torch, Paddle, JAX, DLPack and XLA FFI names. The public ``kdsl.float32``
classes, the runtime's array dtypes, every backend and the interop modules derive
their lists from here; none keeps a second one.

Text forms::

    bool  i8 i16 i32 i64  u8 u16 u32 u64  f16 f32 f64  bf16
    vec<3, f32>   mat<3, 3, f32>   quat<f32>   transform<f32>
    array<vec<3, f32>, 2>   struct<Particle>   handle<mesh>
"""

from __future__ import annotations

from collections.abc import Callable
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


@dataclass(frozen=True, init=False)
class ScalarType(Type):
    """A scalar type, carrying every fact kdsl, its backends and its interop read about it.

    Each scalar is one row of the table below (``BOOL``, ``I8`` ... ``F64``), the only
    place its names and codes are spelled. ``ScalarType(kind, bits)`` returns that row's
    object, so two instances of one type never disagree; equality and hashing use
    ``kind`` and ``bits`` only. Framework names are strings (``"float32"``), never
    framework objects, so ``kdsl.ir`` imports no torch, JAX or llvmlite.
    """

    kind: str
    """One of ``bool``, ``int``, ``uint``, ``float``, ``bfloat`` (bfloat16, a storage type:
    see ``BF16``)."""
    bits: int
    """The width in bits (8 for bool: its size in memory)."""
    name: str = field(compare=False, repr=False)
    """The IR text name: ``bool``, ``i8`` ... ``u64``, ``f16`` ... ``f64``."""
    np_dtype: np.dtype = field(compare=False, repr=False)
    """The NumPy dtype. Its name is also the public class name (``kdsl.float32``, as in Warp)."""
    struct: str = field(compare=False, repr=False)
    """The ``struct`` module code, standard size (for ``<`` formats): packed launch arguments."""
    c: str = field(compare=False, repr=False)
    """The CUDA C spelling (float16 is ``kd_f16``, a struct of the half's bits)."""
    llvm: str = field(compare=False, repr=False)
    """The LLVM register type (bool is ``i1`` in registers, a byte in memory)."""
    suffix: str = field(compare=False, repr=False)
    """Warp's suffix for vector and matrix classes of this type (``vec3d``); ``""`` for none."""
    torch: str = field(compare=False, repr=False)
    """The ``torch`` dtype attribute kdsl converts to: uint16/32/64 become the signed type of
    their width (torch supports those unsigned types only partly; as Warp does)."""
    paddle: str = field(compare=False, repr=False)
    """The ``paddle`` dtype attribute kdsl converts to (Paddle has no uint16/32/64: signed)."""
    jax: str = field(compare=False, repr=False)
    """The ``jax.numpy`` dtype attribute (``bool_`` for bool)."""
    dlpack: tuple[int, int] = field(compare=False, repr=False)
    """DLPack's ``DLDataType`` (type code, bits), one lane: kDLInt 0, kDLUInt 1, kDLFloat 2,
    kDLBool 6 (``dlpack.h``)."""
    xla_ffi: int = field(compare=False, repr=False)
    """The ``XLA_FFI_DataType`` code (``xla/ffi/api/c_api.h``): PRED 1, S8 2 ... F64 12."""

    def __new__(cls, kind: str, bits: int) -> ScalarType:
        try:
            return _BY_KIND_BITS[kind, bits]
        except KeyError:
            raise ValueError(f"kdsl has no {kind} scalar of {bits} bits") from None

    def __reduce__(self) -> tuple[type, tuple[str, int]]:
        return ScalarType, (self.kind, self.bits)

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

    def __str__(self) -> str:
        return self.name


_IR_PREFIX = {"int": "i", "uint": "u", "float": "f", "bfloat": "bf"}
_DLPACK_CODE = {"int": 0, "uint": 1, "float": 2, "bfloat": 4, "bool": 6}  # DLDataTypeCode


def _scalar(
    kind: str,
    bits: int,
    numpy: str,
    struct: str,
    c: str,
    llvm: str,
    suffix: str,
    torch: str,
    jax: str,
    xla_ffi: int,
) -> ScalarType:
    """One row of the scalar table. The IR name and the DLPack type follow from kind and
    bits; torch and Paddle lack the same unsigned types, so one name serves both."""
    t = object.__new__(ScalarType)
    facts = {
        "kind": kind,
        "bits": bits,
        "name": "bool" if kind == "bool" else f"{_IR_PREFIX[kind]}{bits}",
        "np_dtype": np.dtype(numpy),
        "struct": struct,
        "c": c,
        "llvm": llvm,
        "suffix": suffix,
        "torch": torch,
        "paddle": torch,
        "jax": jax,
        "dlpack": (_DLPACK_CODE[kind], bits),
        "xla_ffi": xla_ffi,
    }
    for k, v in facts.items():
        object.__setattr__(t, k, v)
    return t


#: The scalar table: every scalar type, once, by its IR text name. Every other list of
#: scalars derives from it. "st" is the struct code, "sfx" Warp's vector suffix; the torch
#: name is Paddle's too.
# fmt: off
SCALARS: dict[str, ScalarType] = {t.name: t for t in (_scalar(*row) for row in (
    # kind  bits  NumPy      st   C                     LLVM      sfx   torch      JAX       XLA
    ("bool",   8, "bool",    "?", "bool",               "i1",     "",   "bool",    "bool_",    1),
    ("int",    8, "int8",    "b", "signed char",        "i8",     "b",  "int8",    "int8",     2),
    ("int",   16, "int16",   "h", "short",              "i16",    "s",  "int16",   "int16",    3),
    ("int",   32, "int32",   "i", "int",                "i32",    "i",  "int32",   "int32",    4),
    ("int",   64, "int64",   "q", "long long",          "i64",    "l",  "int64",   "int64",    5),
    ("uint",   8, "uint8",   "B", "unsigned char",      "i8",     "ub", "uint8",   "uint8",    6),
    ("uint",  16, "uint16",  "H", "unsigned short",     "i16",    "us", "int16",   "uint16",   7),
    ("uint",  32, "uint32",  "I", "unsigned int",       "i32",    "ui", "int32",   "uint32",   8),
    ("uint",  64, "uint64",  "Q", "unsigned long long", "i64",    "ul", "int64",   "uint64",   9),
    ("float", 16, "float16", "e", "kd_f16",             "half",   "h",  "float16", "float16", 10),
    ("float", 32, "float32", "f", "float",              "float",  "f",  "float32", "float32", 11),
    ("float", 64, "float64", "d", "double",             "double", "d",  "float64", "float64", 12),
    ("bfloat", 16, "uint16", "H", "unsigned short",     "i16",    "",   "bfloat16", "bfloat16", 16),
))}
# fmt: on
BOOL, I8, I16, I32, I64, U8, U16, U32, U64, F16, F32, F64, BF16 = SCALARS.values()
#: bfloat16 (Warp's ``wp.bfloat16``) is a storage type: arrays hold its bits (the NumPy
#: dtype is their ``uint16``), and kernels see float32 values. The frontend converts at
#: each load and store with integer ops (``kdsl/frontend/bfloat16.py``), so a ``bf16``
#: value lives in the IR only between a memory op and its conversion (as 16 bits: the
#: backends treat it as ``u16``), and no backend computes with it.
_BY_KIND_BITS: dict[tuple[str, int], ScalarType] = {(t.kind, t.bits): t for t in SCALARS.values()}
# NumPy has no bfloat16: its storage dtype (uint16) names uint16.
_NUMPY_SCALARS = [t for t in SCALARS.values() if t is not BF16]
_BY_NP_NAME: dict[str, ScalarType] = {t.np_dtype.name: t for t in _NUMPY_SCALARS}
_BY_NP: dict[object, ScalarType] = {
    key: t for t in _NUMPY_SCALARS for key in (t.np_dtype, t.np_dtype.type)
}


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
class NamedVectorType(VectorType):
    """A vector of a fixed length with a name of its own, typed apart from ``vec``.

    Subclasses give the ``keyword`` of the text form (``quat<f32>``) and the length.
    """

    keyword: ClassVar[str]
    fixed_length: ClassVar[int]

    def __init__(self, elem: ScalarType) -> None:
        object.__setattr__(self, "length", self.fixed_length)
        object.__setattr__(self, "elem", elem)

    def __str__(self) -> str:
        return f"{self.keyword}<{self.elem}>"


@dataclass(frozen=True, init=False)
class QuatType(NamedVectorType):
    """A quaternion (x, y, z, w): stored like a 4-vector, typed apart from one."""

    keyword: ClassVar[str] = "quat"
    fixed_length: ClassVar[int] = 4


@dataclass(frozen=True, init=False)
class TransformType(NamedVectorType):
    """A rigid transform (p.x, p.y, p.z, q.x, q.y, q.z, q.w): 7 scalars."""

    keyword: ClassVar[str] = "transform"
    fixed_length: ClassVar[int] = 7


@dataclass(frozen=True)
class StructType(Type):
    """A named record. Equality is by name, fields and alignment, so two definitions agree.

    ``align`` is a declared minimum alignment in bytes (a power of two; 0: C's natural
    alignment, its widest field's). A struct declared ``align=16`` is laid out at a
    multiple of 16 everywhere (its size padded to 16, its offset inside other structs,
    every element of an array of it), so a backend may load it with 16-byte vector
    loads: the cuda backend declares it ``__align__(16)`` and NVRTC then reads a
    32-byte node as two ``ld.v4``. Arrays of it refuse addresses or strides that are
    not multiples of ``align`` (``kdsl.runtime.array``).
    """

    name: str
    fields: tuple[tuple[str, Type], ...] = field(default=())
    align: int = 0

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
        align = f" align {self.align}" if self.align else ""
        return f"struct {self.name}{align} {{{body}}}"


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
    if isinstance(t, NamedVectorType):
        return type(t)(elem)
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
    alignment, the struct aligned to its widest field (or its declared ``align``,
    if larger) and padded to a multiple of that. The cpu backend's field offsets, the CUDA C structs and NumPy's
    structured arrays all read their layout from here, so they agree. Raises
    ``TypeError`` for types with no memory layout (arrays, handles, and structs
    holding them).
    """
    if isinstance(t, ScalarType):
        return t.np_dtype
    if isinstance(t, VectorType | MatrixType):
        return np.dtype((t.elem.np_dtype, t.shape))
    if isinstance(t, StructType):
        hit = _STRUCT_DTYPES.get(id(t))  # (by identity: hashing a struct hashes its fields)
        if hit is None or hit[0] is not t:
            hit = _STRUCT_DTYPES[id(t)] = (t, struct_dtype(t, storage_dtype))
        return hit[1]
    raise TypeError(f"values of {t} cannot be stored in an array")


#: ``storage_dtype`` of each struct type met, by identity (the entry holds the type, so
#: its id is not reused): an array of records asks at every allocation and view.
_STRUCT_DTYPES: dict[int, tuple[StructType, np.dtype]] = {}


def struct_dtype(t: StructType, field_dtype: Callable[[Type], np.dtype]) -> np.dtype:
    """The NumPy dtype of struct ``t`` in C's layout, each field's dtype from
    ``field_dtype(field type)``: each field at the next multiple of its alignment
    (``alignment``), the size padded to the struct's alignment."""
    names, formats, offsets, off = [], [], [], 0
    for name, ft in t.fields:
        fd = field_dtype(ft)
        a = alignment(ft, field_dtype)
        off = (off + a - 1) // a * a
        names.append(name)
        formats.append(fd)
        offsets.append(off)
        off += fd.itemsize
    align = alignment(t, field_dtype)
    size = (off + align - 1) // align * align
    spec = {"names": names, "formats": formats, "offsets": offsets, "itemsize": size}
    return np.dtype(spec, align=True)


def alignment(t: Type, field_dtype: Callable[[Type], np.dtype] | None = None) -> int:
    """The alignment in bytes of a value of ``t`` in memory: for a struct, its declared
    ``align`` or its widest field's, whichever is larger; otherwise the alignment of
    ``field_dtype(t)`` (``storage_dtype``; records pass theirs, which also lays out
    array and handle fields)."""
    field_dtype = storage_dtype if field_dtype is None else field_dtype
    if isinstance(t, StructType):
        return max([1, t.align] + [alignment(ft, field_dtype) for _, ft in t.fields])
    dt = field_dtype(t)
    return dt.alignment if dt.subdtype is None else dt.subdtype[0].alignment
