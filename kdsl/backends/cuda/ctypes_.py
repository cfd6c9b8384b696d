"""IR types as CUDA C types, and their byte layout (for kernel parameters).

Scalars are C's own types, except float16: ``kd_f16``, a struct holding the IEEE
half bits (arithmetic widens to float and rounds back after each op, as the cpu
backend and NumPy do), so no CUDA header is needed. Vectors, quaternions and
transforms are ``struct kd_vec<N>_<t> { T c[N]; }``, matrices ``struct
kd_mat<R>x<C>_<t> { T c[R*C]; }`` (row-major): the same bytes as one element of a
kdsl array, so loads and stores are plain struct copies. User structs become
``struct k_<name>_<n>`` with fields ``f0, f1, ...``: no user identifier reaches
the C source. Arrays are descriptors ``struct kd_array<N> { char *data; long long
shape[N]; long long strides[N]; }`` with strides in bytes.
"""

from __future__ import annotations

import re

from kdsl.errors import KdslCapabilityError
from kdsl.ir import types as T

#: C spelling of each scalar type (bool is C++ ``bool``, one byte).
_SCALAR_C = {
    ("bool", 8): "bool",
    ("int", 8): "signed char", ("int", 16): "short", ("int", 32): "int", ("int", 64): "long long",
    ("uint", 8): "unsigned char", ("uint", 16): "unsigned short", ("uint", 32): "unsigned int",
    ("uint", 64): "unsigned long long",
    ("float", 16): "kd_f16", ("float", 32): "float", ("float", 64): "double",
}  # fmt: skip

#: Short tag of each scalar type, used in generated type names.
_TAG = {
    ("bool", 8): "b", ("int", 8): "i8", ("int", 16): "i16", ("int", 32): "i32",
    ("int", 64): "i64", ("uint", 8): "u8", ("uint", 16): "u16", ("uint", 32): "u32",
    ("uint", 64): "u64", ("float", 16): "f16", ("float", 32): "f32", ("float", 64): "f64",
}  # fmt: skip


def scalar_c(t: T.ScalarType) -> str:
    """The C type of a scalar."""
    return _SCALAR_C[(t.kind, t.bits)]


def tag(t: T.ScalarType) -> str:
    """The short tag (``f32``...) of a scalar type."""
    return _TAG[(t.kind, t.bits)]


def unsigned_c(t: T.ScalarType) -> str:
    """An unsigned C type at least 32 bits wide holding ``t``'s bits (for wrapping math)."""
    return "unsigned long long" if t.bits == 64 else "unsigned int"


def count(t: T.Type) -> int:
    """Number of scalar components of a scalar, vector or matrix."""
    if isinstance(t, T.ScalarType):
        return 1
    n = 1
    for d in T.value_shape(t):
        n *= d
    return n


def composite_name(t: T.Type) -> str:
    """The C struct name of a vector-like or matrix type."""
    if isinstance(t, T.MatrixType):
        return f"kd_mat{t.rows}x{t.cols}_{tag(t.elem)}"
    return f"kd_vec{t.length}_{tag(t.elem)}"


def sanitize(name: str) -> str:
    """``name`` reduced to ASCII letters, digits and underscores (for readability only)."""
    s = re.sub(r"[^A-Za-z0-9_]", "_", name)
    return re.sub(r"_+", "_", s).strip("_")[:40] or "x"


def array_name(ndim: int) -> str:
    """The C struct name of an ``ndim``-d array descriptor."""
    return f"kd_array{ndim}"


def layout(t: T.Type) -> tuple[int, int]:
    """(size, alignment) in bytes of a by-value kernel parameter of type ``t``."""
    if isinstance(t, T.ScalarType):
        n = max(1, t.bits // 8)
        return n, n
    if isinstance(t, T.VectorType | T.MatrixType):
        s, a = layout(t.elem)
        return s * count(t), a
    if isinstance(t, T.ArrayType):
        return 8 * (1 + 2 * t.ndim), 8
    if isinstance(t, T.StructType):
        off, align = 0, 1
        for _, ft in t.fields:
            s, a = layout(ft)
            off = (off + a - 1) // a * a + s
            align = max(align, a)
        return (off + align - 1) // align * align, align
    if isinstance(t, T.HandleType):
        return 8, 8
    raise KdslCapabilityError(f"the cuda backend cannot pass values of type {t}")
