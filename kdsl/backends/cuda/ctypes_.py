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

import math
import re

from kdsl.errors import KdslCapabilityError
from kdsl.ir import types as T


def scalar_c(t: T.ScalarType) -> str:
    """The C type of a scalar (bool is C++ ``bool``, one byte)."""
    return t.c


def tag(t: T.ScalarType) -> str:
    """The short tag of a scalar type in generated type names: its IR name, bool ``b``."""
    return "b" if t.is_bool else t.name


def unsigned_c(t: T.ScalarType) -> str:
    """An unsigned C type at least 32 bits wide holding ``t``'s bits (for wrapping math)."""
    return "unsigned long long" if t.bits == 64 else "unsigned int"


def count(t: T.Type) -> int:
    """Number of scalar components of a scalar, vector or matrix."""
    return math.prod(T.value_shape(t))


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
        n = t.np_dtype.itemsize
        return n, n
    if isinstance(t, T.VectorType | T.MatrixType):
        s, a = layout(t.elem)
        return s * count(t), a
    if isinstance(t, T.ArrayType):
        return 8 * (1 + 2 * t.ndim), 8
    if isinstance(t, T.StructType):
        off, align = 0, max(1, t.align)  # a declared ``align`` (C's ``__align__``)
        for _, ft in t.fields:
            s, a = layout(ft)
            off = (off + a - 1) // a * a + s
            align = max(align, a)
        return (off + align - 1) // align * align, align
    if isinstance(t, T.HandleType):
        return 8, 8
    raise KdslCapabilityError(f"the cuda backend cannot pass values of type {t}")
