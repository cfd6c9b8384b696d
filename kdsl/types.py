"""Public kdsl types: ``float32``, ``vec3``, ``mat33``, ``quat``, ``transform``...

These are the names users write in annotations and in Python scope, as in Warp.
Each class carries ``__kdsl_type__``, its IR type (from ``kdsl.ir.types``, the one
dtype table). ``type_of(annotation)`` turns any annotation into an IR type.

In Python scope, ``kdsl.float32(1.5)`` gives a NumPy ``float32`` and
``kdsl.vec3(1, 2, 3)`` gives a ``vec3`` (a NumPy array subclass of shape (3,)). Its
operators follow the kernel language, as Warp's do: ``+ - * / @`` and unary ``-`` are
evaluated with the kernel's own semantics (``m * v`` is a matrix product, ``q1 * q2`` the
quaternion product, ``t1 * t2`` composes transforms) through the hook the compiler
registers (``register_python_scope``); ``==`` is one bool; indexing and iteration give
scalars and rows as kdsl values; ``v.x``/``t.p``/``t.q`` name parts as in kernels.
"""

from __future__ import annotations

import builtins
from typing import Any

import numpy as np

from kdsl.ir import bfloat16 as bfloat16_bits
from kdsl.ir import types as T

__all__ = [
    "Scalar", "Composite", "bool", "int8", "int16", "int32", "int64", "uint8", "uint16",
    "uint32", "uint64", "float16", "float32", "float64", "bfloat16", "half", "vector", "matrix",
    "quaternion", "transformation", "vec2", "vec3", "vec4", "vec2f", "vec3f", "vec4f",
    "vec2d", "vec3d", "vec4d", "vec2h", "vec3h", "vec4h", "vec2i", "vec3i", "vec4i",
    "vec2ui", "vec3ui", "vec4ui", "vec2b", "vec3b", "vec4b", "vec2ub", "vec3ub", "vec4ub",
    "vec2s", "vec3s", "vec4s", "vec2us", "vec3us", "vec4us", "vec2l", "vec3l", "vec4l",
    "vec2ul", "vec3ul", "vec4ul", "mat22", "mat33", "mat44", "mat22f", "mat33f", "mat44f",
    "mat22d", "mat33d", "mat44d", "mat22h", "mat33h", "mat44h", "quat", "quatf", "quatd",
    "quath", "transform", "transformf", "transformd", "transformh", "spatial_vector",
    "spatial_vectorf", "spatial_vectord", "spatial_vectorh", "spatial_matrix", "spatial_matrixf",
    "spatial_matrixd", "spatial_matrixh", "type_of", "class_of",
    "dtype_to_numpy", "dtype_from_numpy", "types_equal", "type_is_scalar", "type_is_float",
    "type_is_int", "type_is_vector", "type_is_matrix", "type_is_quaternion",
    "type_is_transformation", "type_size", "type_size_in_bytes",
]  # fmt: skip


class Scalar:
    """Base of the scalar type classes. Calling one converts a Python value."""

    __kdsl_type__: T.ScalarType

    def __new__(cls, value: Any = 0) -> Any:  # type: ignore[misc]
        return cls.__kdsl_type__.np_dtype.type(value)


def _bfloat16_value(value: Any = 0.0) -> np.float32:
    """``kdsl.bfloat16(x)``: ``x`` rounded to bfloat16, as the float32 kernels compute with."""
    return bfloat16_bits.from_bits(bfloat16_bits.to_bits(value))[()]


def _scalar(t: T.ScalarType) -> type:
    if t is T.BF16:  # a storage type: its values are float32 (see kdsl.ir.types.BF16)
        ns = {"__kdsl_type__": t, "__new__": staticmethod(lambda cls, v=0.0: _bfloat16_value(v)),
              "__doc__": "The bfloat16 storage type (values are float32 rounded to it)."}  # fmt: skip
        return type("bfloat16", (Scalar,), ns)
    name = t.np_dtype.name  # Warp names its scalars as NumPy does
    return type(name, (Scalar,), {"__kdsl_type__": t, "__doc__": f"The {t} scalar type."})


#: The public class of each scalar type, one per row of the IR's scalar table.
SCALAR_CLASSES: dict[T.ScalarType, type] = {t: _scalar(t) for t in T.SCALARS.values()}

# The public names, spelled out so that tools and readers see them.
bool = SCALAR_CLASSES[T.BOOL]  # noqa: A001 - Warp's name
int8 = SCALAR_CLASSES[T.I8]
int16 = SCALAR_CLASSES[T.I16]
int32 = SCALAR_CLASSES[T.I32]
int64 = SCALAR_CLASSES[T.I64]
uint8 = SCALAR_CLASSES[T.U8]
uint16 = SCALAR_CLASSES[T.U16]
uint32 = SCALAR_CLASSES[T.U32]
uint64 = SCALAR_CLASSES[T.U64]
float16 = SCALAR_CLASSES[T.F16]
float32 = SCALAR_CLASSES[T.F32]
float64 = SCALAR_CLASSES[T.F64]
bfloat16 = SCALAR_CLASSES[T.BF16]
half = float16


_EVALUATOR: list[Any] = []


def register_python_scope(evaluator: Any) -> None:
    """Install the Python-scope evaluator (``kdsl.compiler.python_scope.call``).

    The compiler sits above this module; it hands its evaluator down once, when it is
    imported (``import kdsl`` does that).
    """
    _EVALUATOR[:] = [evaluator]


def python_scope(what: Any, args: tuple, kwargs: dict[str, Any] | None = None) -> Any:
    """``what(*args, **kwargs)`` evaluated in Python scope with kernel semantics.

    ``what`` is a kernel builtin, a standard-library ``@kdsl.func`` or an operator name
    (``"add"``, ``"sub"``, ``"mul"``, ``"truediv"``, ``"floordiv"``, ``"mod"``,
    ``"matmul"``, ``"neg"``, ``"pos"``).
    """
    if not _EVALUATOR:
        from kdsl.errors import KdslError

        raise KdslError("the Python-scope evaluator is not registered: import kdsl first")
    return _EVALUATOR[0](what, args, kwargs or {})


def _operand(x: Any) -> bool:
    """True for what a composite's operator evaluates with kernel semantics."""
    return isinstance(x, Composite | builtins.int | builtins.float) or (
        isinstance(x, np.generic) and x.dtype.kind in "biuf"
    )


def _binary(name: str, reflected: builtins.bool = False) -> Any:
    numpy_op = getattr(np.ndarray, f"__{'r' if reflected else ''}{name}__")

    def op(self: Composite, other: Any) -> Any:
        if not _operand(other):
            # Plain arrays, lists...: NumPy's elementwise rule, on a plain array.
            return numpy_op(self.view(np.ndarray), other)
        return python_scope(name, (other, self) if reflected else (self, other))

    op.__name__ = f"__{'r' if reflected else ''}{name}__"
    op.__doc__ = f"The kernel's ``{name}`` of two kdsl values (see ``python_scope``)."
    return op


class Composite(np.ndarray):
    """Base of vector, matrix, quaternion and transform classes (Python scope values).

    A NumPy array of the type's shape (``np.asarray(v)`` is free), with the kernel
    language's operators (Warp's Python-scope semantics); see the module docstring.
    """

    __kdsl_type__: T.Type

    def __new__(cls, *args: Any) -> Composite:
        t = cls.__kdsl_type__
        shape = T.value_shape(t)
        dtype = T.elem_type(t).np_dtype
        size = int(np.prod(shape))
        if not args:
            flat = np.zeros(size, dtype)
        elif len(args) == 1 and np.ndim(args[0]) == 0:
            flat = np.full(size, args[0], dtype)
        else:
            flat = np.concatenate([np.ravel(np.asarray(a, dtype)) for a in args])
            if flat.size != size:
                from kdsl.errors import KdslTypeError

                raise KdslTypeError(f"{cls.__name__} takes {size} components, got {flat.size}")
        return flat.reshape(shape).view(cls)

    __add__, __radd__ = _binary("add"), _binary("add", True)
    __sub__, __rsub__ = _binary("sub"), _binary("sub", True)
    __mul__, __rmul__ = _binary("mul"), _binary("mul", True)
    __truediv__, __rtruediv__ = _binary("truediv"), _binary("truediv", True)
    __floordiv__, __rfloordiv__ = _binary("floordiv"), _binary("floordiv", True)
    __mod__, __rmod__ = _binary("mod"), _binary("mod", True)
    __matmul__, __rmatmul__ = _binary("matmul"), _binary("matmul", True)

    def __neg__(self) -> Any:
        return python_scope("neg", (self,))

    def __pos__(self) -> Any:
        return python_scope("pos", (self,))

    def __eq__(self, other: Any) -> builtins.bool:  # type: ignore[override]
        """One bool, as in Warp: the same shape and every component equal."""
        try:
            b = np.asarray(other)
        except Exception:
            return False
        a = self.view(np.ndarray)
        return a.shape == b.shape and builtins.bool(np.all(a == b))

    def __ne__(self, other: Any) -> builtins.bool:  # type: ignore[override]
        return not self.__eq__(other)

    __hash__ = None  # type: ignore[assignment]  # mutable, as NumPy arrays are

    def __getitem__(self, index: Any) -> Any:
        """A component (a NumPy scalar), a matrix row or a slice (kdsl vectors)."""
        return _as_value(self.view(np.ndarray)[index])

    def __iter__(self) -> Any:
        for k in range(len(self)):
            yield self[k]

    def __array_wrap__(self, arr: Any, context: Any = None, return_scalar: Any = False) -> Any:
        # NumPy functions on a composite: keep the class only where the shape and kind
        # still fit it (np.sin(v) is a vec3, np.isnan(v) a plain bool array).
        out = np.ndarray.__array_wrap__(self, arr, context, return_scalar)
        if isinstance(out, np.ndarray) and not (
            out.shape == self.shape and out.dtype == self.dtype
        ):
            return _as_value(out.view(np.ndarray))
        return out

    def __reduce__(self) -> Any:
        return (_rebuild, (type(self).__kdsl_type__, self.view(np.ndarray).tolist()))

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.view(np.ndarray).tolist()})"

    __str__ = __repr__

    def __getattr__(self, name: str) -> Any:
        index = _PART_INDEX.get(name)
        t = type(self).__kdsl_type__
        if _has_part(t, index):
            return self[index]
        if isinstance(t, T.TransformType) and name in ("p", "q"):
            return self[0:3] if name == "p" else _as_value(self.view(np.ndarray)[3:7], T.QuatType)
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    def __setattr__(self, name: str, value: Any) -> None:
        index = _PART_INDEX.get(name)
        t = type(self).__kdsl_type__
        if _has_part(t, index):
            self.view(np.ndarray)[index] = value
            return
        if isinstance(t, T.TransformType) and name in ("p", "q"):
            part = slice(0, 3) if name == "p" else slice(3, 7)
            self.view(np.ndarray)[part] = np.ravel(np.asarray(value))
            return
        object.__setattr__(self, name, value)


_PART_INDEX = {"x": 0, "y": 1, "z": 2, "w": 3}


def _has_part(t: T.Type, index: int | None) -> builtins.bool:
    """True when component ``index`` (of ``.x``...``.w``) exists on a vector or quaternion."""
    return (
        index is not None
        and isinstance(t, T.VectorType | T.QuatType)
        and index < T.value_shape(t)[0]
    )


def _rebuild(t: T.Type, values: list) -> Composite:
    return class_of(t)(np.asarray(values))


def _as_value(x: Any, kind: type | None = None) -> Any:
    """A piece of a composite as a Python-scope value: a scalar or a vector/matrix class."""
    if not isinstance(x, np.ndarray):
        return x
    if x.ndim == 0:
        return x[()]
    try:
        et = T.scalar_from_numpy(x.dtype)
    except (KeyError, TypeError):
        return x
    if kind is T.QuatType and x.shape == (4,):
        return x.copy().view(class_of(T.QuatType(et)))
    if x.ndim == 1 and x.shape[0] > 0:
        return x.view(class_of(T.VectorType(x.shape[0], et)))
    if x.ndim == 2 and x.shape[0] > 0 and x.shape[1] > 0:
        return x.view(class_of(T.MatrixType(x.shape[0], x.shape[1], et)))
    return x


_COMPOSITE_CACHE: dict[T.Type, type] = {}


def _composite(t: T.Type, name: str) -> type:
    cls = _COMPOSITE_CACHE.get(t)
    if cls is None:
        cls = type(name, (Composite,), {"__kdsl_type__": t, "__doc__": f"The {t} type."})
        _COMPOSITE_CACHE[t] = cls
    return cls


def _scalar_type(dtype: Any) -> T.ScalarType:
    t = type_of(dtype)
    if not isinstance(t, T.ScalarType):
        raise TypeError(f"expected a scalar dtype, got {dtype!r}")
    if t is T.BF16:
        raise TypeError("bfloat16 is a storage type: no vectors or matrices of it")
    return t


def vector(length: int, dtype: Any = float32) -> type:
    """The vector class of ``length`` components of ``dtype``."""
    et = _scalar_type(dtype)
    return _composite(T.VectorType(length, et), f"vec{length}{et.suffix}")


def matrix(shape: tuple[int, int], dtype: Any = float32) -> type:
    """The matrix class of ``shape`` (rows, cols) of ``dtype``."""
    et = _scalar_type(dtype)
    r, c = shape
    return _composite(T.MatrixType(r, c, et), f"mat{r}{c}{et.suffix}")


def quaternion(dtype: Any = float32) -> type:
    """The quaternion class of ``dtype``."""
    et = _scalar_type(dtype)
    return _composite(T.QuatType(et), f"quat{et.suffix}")


def transformation(dtype: Any = float32) -> type:
    """The rigid transform class of ``dtype``."""
    et = _scalar_type(dtype)
    return _composite(T.TransformType(et), f"transform{et.suffix}")


_PY_BUILTINS: dict[Any, T.Type] = {
    builtins.float: T.F32,
    builtins.int: T.I32,
    builtins.bool: T.BOOL,
}


def type_of(annotation: Any) -> T.Type:
    """The IR type an annotation or dtype names.

    Accepts Python's ``float`` (f32), ``int`` (i32) and ``bool``; kdsl type classes;
    NumPy scalar types and dtypes; IR types; and anything with ``__kdsl_type__``
    (array annotations, structs). Raises ``TypeError`` otherwise.
    """
    if isinstance(annotation, T.Type):
        return annotation
    if annotation in _PY_BUILTINS:
        return _PY_BUILTINS[annotation]
    t = getattr(annotation, "__kdsl_type__", None)
    if isinstance(t, T.Type):
        return t
    try:
        return T.scalar_from_numpy(annotation)
    except (KeyError, TypeError):
        pass
    raise TypeError(f"{annotation!r} is not a kdsl type")


def class_of(t: T.Type) -> type:
    """The public class of an IR value type (the inverse of ``type_of``)."""
    if isinstance(t, T.ScalarType):
        return SCALAR_CLASSES[t]
    if isinstance(t, T.QuatType):
        return quaternion(SCALAR_CLASSES[t.elem])
    if isinstance(t, T.TransformType):
        return transformation(SCALAR_CLASSES[t.elem])
    if isinstance(t, T.VectorType):
        return vector(t.length, SCALAR_CLASSES[t.elem])
    if isinstance(t, T.MatrixType):
        return matrix((t.rows, t.cols), SCALAR_CLASSES[t.elem])
    raise TypeError(f"{t} has no public value class")


def dtype_to_numpy(dtype: Any) -> np.dtype:
    """The NumPy dtype of a kdsl scalar type (vectors: of their elements)."""
    return T.elem_type(type_of(dtype)).np_dtype


def dtype_from_numpy(dtype: Any) -> type:
    """The kdsl scalar class of a NumPy dtype; a ``KdslTypeError`` for one kdsl lacks."""
    try:
        return SCALAR_CLASSES[T.scalar_from_numpy(dtype)]
    except (KeyError, TypeError):
        from kdsl.errors import KdslTypeError

        raise KdslTypeError(
            f"NumPy dtype {np.dtype(dtype).name if _is_dtype(dtype) else repr(dtype)} has no kdsl "
            "equivalent (kdsl has bool, int8..int64, uint8..uint64, float16, float32, float64)"
        ) from None


# --- Warp's type queries (``wp.types.types_equal`` ...), for ``wp.static`` conditions ----


def _ir_type(t: Any) -> T.Type | None:
    if isinstance(t, str):  # type_of reads NumPy's names; Warp's queries do not
        return None
    try:
        return type_of(t)
    except TypeError:
        return None


def types_equal(a: Any, b: Any) -> builtins.bool:
    """True when ``a`` and ``b`` name one type (``float`` and ``float32`` do), as Warp's."""
    ta, tb = _ir_type(a), _ir_type(b)
    return a is b or (ta is not None and ta == tb)


def type_is_scalar(t: Any) -> builtins.bool:
    """True for a numeric scalar type (integers, floats; ``bool`` is not one, as in Warp)."""
    ir = _ir_type(t)
    return isinstance(ir, T.ScalarType) and not ir.is_bool


def type_is_float(t: Any) -> builtins.bool:
    """True for a floating-point scalar type (``float`` and ``bfloat16`` included)."""
    ir = _ir_type(t)
    return isinstance(ir, T.ScalarType) and (ir.is_float or ir.kind == "bfloat")


def type_is_int(t: Any) -> builtins.bool:
    """True for a signed or unsigned integer type (not ``bool``)."""
    ir = _ir_type(t)
    return isinstance(ir, T.ScalarType) and ir.is_int


def type_is_vector(t: Any) -> builtins.bool:
    """True for a vector type; quaternions and transforms are not (as in Warp)."""
    ir = _ir_type(t)
    return isinstance(ir, T.VectorType) and not isinstance(ir, T.NamedVectorType)


def type_is_matrix(t: Any) -> builtins.bool:
    """True for a matrix type."""
    return isinstance(_ir_type(t), T.MatrixType)


def type_is_quaternion(t: Any) -> builtins.bool:
    """True for a quaternion type."""
    return isinstance(_ir_type(t), T.QuatType)


def type_is_transformation(t: Any) -> builtins.bool:
    """True for a transform type."""
    return isinstance(_ir_type(t), T.TransformType)


def type_size(t: Any) -> int:
    """The number of scalars in a value of type ``t`` (1 for a scalar, 9 for ``mat33``)."""
    ir = _ir_type(t)
    if isinstance(ir, T.ScalarType):
        return 1
    if isinstance(ir, T.VectorType | T.MatrixType):
        return int(np.prod(ir.shape))
    raise TypeError(f"type_size() takes a scalar, vector or matrix type, not {t!r}")


def type_size_in_bytes(t: Any) -> int:
    """The size in bytes of a value of scalar, vector or matrix type ``t``."""
    return type_size(t) * T.elem_type(type_of(t)).np_dtype.itemsize


def _is_dtype(dtype: Any) -> bool:
    try:
        np.dtype(dtype)
    except TypeError:
        return False
    return True


vec2, vec3, vec4 = (vector(n) for n in (2, 3, 4))
vec2f, vec3f, vec4f = vec2, vec3, vec4
vec2d, vec3d, vec4d = (vector(n, float64) for n in (2, 3, 4))
vec2h, vec3h, vec4h = (vector(n, float16) for n in (2, 3, 4))
vec2i, vec3i, vec4i = (vector(n, int32) for n in (2, 3, 4))
vec2ui, vec3ui, vec4ui = (vector(n, uint32) for n in (2, 3, 4))
vec2b, vec3b, vec4b = (vector(n, int8) for n in (2, 3, 4))
vec2ub, vec3ub, vec4ub = (vector(n, uint8) for n in (2, 3, 4))
vec2s, vec3s, vec4s = (vector(n, int16) for n in (2, 3, 4))
vec2us, vec3us, vec4us = (vector(n, uint16) for n in (2, 3, 4))
vec2l, vec3l, vec4l = (vector(n, int64) for n in (2, 3, 4))
vec2ul, vec3ul, vec4ul = (vector(n, uint64) for n in (2, 3, 4))
mat22, mat33, mat44 = (matrix((n, n)) for n in (2, 3, 4))
mat22f, mat33f, mat44f = mat22, mat33, mat44
mat22d, mat33d, mat44d = (matrix((n, n), float64) for n in (2, 3, 4))
mat22h, mat33h, mat44h = (matrix((n, n), float16) for n in (2, 3, 4))
quat = quatf = quaternion()
quatd, quath = quaternion(float64), quaternion(float16)
transform = transformf = transformation()
transformd, transformh = transformation(float64), transformation(float16)
# Spatial (6D) vectors and matrices, as in Warp: (angular, linear) halves.
spatial_vector = spatial_vectorf = vector(6)
spatial_vectord, spatial_vectorh = vector(6, float64), vector(6, float16)
spatial_matrix = spatial_matrixf = matrix((6, 6))
spatial_matrixd, spatial_matrixh = matrix((6, 6), float64), matrix((6, 6), float16)
