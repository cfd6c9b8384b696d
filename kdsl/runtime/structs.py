"""``@kdsl.struct``: user record types and their Python-scope values.

A decorated class becomes a ``Struct`` subclass whose ``__kdsl_type__`` is an IR
``StructType`` (fields in declaration order). Fields may be any kdsl value type,
arrays (``wp.array(dtype=...)``) and other structs.

- Python scope: ``p = Particle()`` zero-fills every field (arrays start as None);
  assigning a field checks and converts the value (``p.m = 2`` stores a float32).
  An instance is a kernel argument; the launch reads its fields (``as_tuple``).
- Kernels see only the IR ``StructType``; ``kdsl.frontend.structs`` lowers
  ``Particle(...)``, ``p.x`` and ``p.x = v`` there.
- Arrays of structs: ``numpy_dtype()`` is the element layout (C natural alignment,
  ``kdsl.ir.types.storage_dtype``), shared by NumPy, the cpu and the cuda backend.
"""

from __future__ import annotations

import ast
import inspect
import sys
import textwrap
from typing import Any, ClassVar

import numpy as np

from kdsl.errors import KdslTypeError
from kdsl.ir import Loc
from kdsl.ir.types import BF16, ArrayType, StructType, Type, storage_dtype
from kdsl.runtime.args import ArgError, convert_composite, convert_scalar
from kdsl.runtime.array import array
from kdsl.types import class_of, type_of

#: StructType -> its public class (for ``array.dtype`` and element conversion).
_CLASSES: dict[StructType, type] = {}
#: IR names taken so far: two different classes of one name get distinct IR names.
_NAMES: dict[str, StructType] = {}


class _StructMeta(type):
    # Named by the IR type: two struct classes of one Python name (a factory's) differ
    # in repr, so @kdsl.func overloads on them stay apart.
    def __repr__(cls) -> str:
        st = cls.__dict__.get("__kdsl_type__")
        return (
            f"<kdsl.struct {st.name} ({cls.__module__}.{cls.__qualname__})>"
            if st
            else super().__repr__()
        )


class Struct(metaclass=_StructMeta):
    """Base of every ``@kdsl.struct`` class (see the module docstring)."""

    __kdsl_type__: ClassVar[StructType]
    #: Field names: the keywords a kernel-side constructor accepts.
    __kdsl_keywords__: ClassVar[tuple[str, ...]] = ()

    def __init__(self, **fields: Any) -> None:
        for name, ft in self.__kdsl_type__.fields:
            object.__setattr__(self, name, _zero(ft))
        for name, value in fields.items():
            setattr(self, name, value)

    def __setattr__(self, name: str, value: Any) -> None:
        st = self.__kdsl_type__
        try:
            ft = st.field_type(name)
        except KeyError:
            raise KdslTypeError(
                f"struct {type(self).__name__} has no field '{name}' (it has: "
                f"{', '.join(n for n, _ in st.fields)})"
            ) from None
        object.__setattr__(self, name, _convert(type(self).__name__, name, ft, value))

    def as_tuple(self) -> tuple:
        """The field values in declaration order (how launches read an instance)."""
        return tuple(getattr(self, n) for n, _ in self.__kdsl_type__.fields)

    @classmethod
    def numpy_dtype(cls) -> np.dtype:
        """The NumPy structured dtype of one element of an array of this struct."""
        try:
            return storage_dtype(cls.__kdsl_type__)
        except TypeError:
            raise KdslTypeError(f"struct {cls.__name__} holds arrays, so it has no NumPy layout "
                                "(it cannot be an array element)") from None  # fmt: skip

    def numpy_value(self) -> tuple:
        """This instance as a NumPy structured-array element (nested tuples)."""
        out = []
        for v in self.as_tuple():
            if isinstance(v, Struct):
                out.append(v.numpy_value())
            elif v is None or not isinstance(v, np.ndarray | np.generic):
                raise KdslTypeError(f"a {type(self).__name__} holding arrays cannot be stored in "
                                    "an array")  # fmt: skip
            else:
                out.append(v)
        return tuple(out)

    @classmethod
    def from_numpy(cls, element: Any) -> Struct:
        """An instance from one element of a structured array of this struct."""
        out = cls()
        for name, ft in cls.__kdsl_type__.fields:
            v = element[name]
            sub = _CLASSES.get(ft) if isinstance(ft, StructType) else None
            setattr(out, name, sub.from_numpy(v) if sub is not None else np.array(v))
        return out

    def __eq__(self, other: Any) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        return all(_same(a, b) for a, b in zip(self.as_tuple(), other.as_tuple()))

    __hash__ = None  # type: ignore[assignment]  # mutable

    def __repr__(self) -> str:
        body = ", ".join(f"{n}={_short(getattr(self, n))}" for n, _ in self.__kdsl_type__.fields)
        return f"{type(self).__name__}({body})"


def struct(cls: type | None = None, *, align: int | None = None) -> Any:
    """Decorate a class with annotated fields into a kdsl struct type (as ``wp.struct``).

    ``@kdsl.struct(align=16)`` (kdsl only) declares a minimum alignment in bytes, a power
    of two: the struct's size is padded to it and every array of it must be aligned to
    it, so the cuda backend loads an element with 16-byte vector loads
    (``kdsl.ir.types.StructType``)."""
    if cls is None:
        return lambda c: _make_struct(c, align, sys._getframe(1).f_locals)
    return _make_struct(cls, align, sys._getframe(1).f_locals)


#: The largest alignment a struct may declare (a CUDA ``__align__`` limit is far above;
#: no load is wider than 16 bytes, and 256 covers cache-line padding).
MAX_ALIGN = 256


def _check_align(cls: Any, align: Any) -> int:
    if align is None:
        return 0
    if (
        isinstance(align, bool)
        or not isinstance(align, int | np.integer)
        or not (1 <= align <= MAX_ALIGN and align & (align - 1) == 0)
    ):
        raise KdslTypeError(
            f"struct {getattr(cls, '__name__', cls)}: align must be a power of two from 1 to "
            f"{MAX_ALIGN}, not {align!r}", _class_loc(cls) if isinstance(cls, type) else None,
        )  # fmt: skip
    return int(align)


def _make_struct(cls: Any, align: Any, caller_locals: dict[str, Any]) -> type:
    if not isinstance(cls, type):
        raise KdslTypeError(f"@kdsl.struct decorates a class, not {cls!r}")
    declared = _check_align(cls, align)
    anns = inspect.get_annotations(cls)
    if not anns:
        raise KdslTypeError(f"struct {cls.__name__} has no annotated fields", _class_loc(cls))
    # String annotations (``from __future__ import annotations``) may name the caller's
    # locals (a struct defined inside a factory function), as in Warp.
    scope = {**vars(sys.modules.get(cls.__module__, sys)), **caller_locals}
    fields = tuple((name, _field_type(cls, name, ann, scope)) for name, ann in anns.items())
    st = StructType(_ir_name(cls.__name__, fields, declared), fields, declared)
    ns = {
        "__kdsl_type__": st, "__kdsl_keywords__": tuple(anns), "__doc__": cls.__doc__,
        "__module__": cls.__module__, "__qualname__": cls.__qualname__,
        # A class-level value of a field is Python-side only; Warp ignores it too.
        **{k: v for k, v in cls.__dict__.items() if callable(v) and not k.startswith("__")},
    }  # fmt: skip
    out = _StructMeta(cls.__name__, (Struct,), ns)
    _CLASSES.setdefault(st, out)
    return out


def _ir_name(name: str, fields: tuple, align: int) -> str:
    """``name``, or ``name_N`` when another struct of that name has other fields (or
    another alignment)."""
    cand, n = name, 1
    while cand in _NAMES and (_NAMES[cand].fields, _NAMES[cand].align) != (fields, align):
        n += 1
        cand = f"{name}_{n}"
    _NAMES[cand] = StructType(cand, fields, align)
    return cand


def _field_type(cls: type, name: str, ann: Any, scope: dict[str, Any]) -> Type:
    """The IR type of field ``name``; a KdslTypeError at the field's line otherwise."""

    if isinstance(ann, str):
        try:
            ann = eval(ann, dict(scope))
        except Exception:
            raise KdslTypeError(f"cannot resolve the annotation {ann!r} of field '{name}' of "
                                f"struct {cls.__name__}", _class_loc(cls, name)) from None  # fmt: skip
    try:
        t = type_of(ann)
    except (TypeError, KdslTypeError):
        t = None
    if t is BF16:
        raise KdslTypeError(
            f"field '{name}' of struct {cls.__name__} is a bfloat16, a storage type in kdsl: "
            "make it a float32 (arrays of bfloat16 may be fields)", _class_loc(cls, name),
        )  # fmt: skip
    if t is None or not (t.is_value or isinstance(t, ArrayType)):
        raise KdslTypeError(
            f"field '{name}' of struct {cls.__name__} has type {_ann_name(ann)}, which a struct "
            "cannot hold (fields are scalars, vectors, matrices, quaternions, transforms, "
            "arrays or structs)", _class_loc(cls, name),
        )  # fmt: skip
    return t


def _ann_name(ann: Any) -> str:
    return getattr(ann, "__name__", None) or repr(ann)


def _class_loc(cls: type, field: str | None = None) -> Loc | None:
    """Where ``cls`` (or its field ``field``) is defined, when its source is readable."""
    try:
        lines, first = inspect.getsourcelines(cls)
        file = inspect.getsourcefile(cls) or "<unknown>"
    except (OSError, TypeError):
        return None
    indent = len(lines[0]) - len(lines[0].lstrip())
    tree = ast.parse(textwrap.dedent("".join(lines)))
    node: ast.AST = tree.body[0]
    for stmt in getattr(node, "body", []):
        target = getattr(stmt, "target", None)
        if isinstance(stmt, ast.AnnAssign) and isinstance(target, ast.Name) and target.id == field:
            node = stmt
    return Loc(file, node.lineno + first - 1, node.col_offset + indent + 1,
               node.end_lineno + first - 1, node.end_col_offset + indent + 1)  # fmt: skip


# --- Python-side values --------------------------------------------------------------


def _zero(t: Type) -> Any:
    if isinstance(t, StructType):
        return _CLASSES[t]()
    if isinstance(t, ArrayType):
        return None
    if t.is_scalar:
        return t.np_dtype.type(0)
    return class_of(t)()


def _convert(sname: str, fname: str, t: Type, value: Any) -> Any:
    """``value`` checked and converted for a field of type ``t``."""
    where = f"field '{fname}' of struct {sname}"
    if isinstance(t, StructType):
        if getattr(type(value), "__kdsl_type__", None) != t:
            raise KdslTypeError(f"{where} holds a {_CLASSES[t].__name__}, not {value!r}")
        return value
    if isinstance(t, ArrayType):
        if value is None:
            return None
        if not isinstance(value, array) or value._t != t.dtype or value.ndim != t.ndim:
            raise KdslTypeError(f"{where} holds a {t.ndim}-d array of {t.dtype}, not "
                                f"{_short(value)}")  # fmt: skip
        return value
    try:
        if t.is_scalar:
            if isinstance(value, float) and t.is_int:  # Warp truncates here; kdsl refuses
                raise ArgError(f"expected {t}, got float {value!r}")
            return convert_scalar(t, value)  # type: ignore[arg-type]
        if isinstance(value, int | float) and not isinstance(value, bool):
            raise ArgError(f"expected {t}, got a single number; construct it, e.g. "
                           f"{class_of(t).__name__}(...)")  # fmt: skip
        return class_of(t)(convert_composite(t, value))
    except ArgError as e:
        raise KdslTypeError(f"{where}: {e}") from None


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, np.ndarray | np.generic):
        return bool(np.array_equal(a, b))
    return a is b if a is None or b is None else a == b


def _short(v: Any) -> str:
    if isinstance(v, np.ndarray):
        return str(v.tolist())
    return repr(v) if not hasattr(v, "_t") else f"array of {v._t}"


def class_of_struct(t: StructType) -> type:
    """The public class of struct type ``t``."""
    return _CLASSES[t]


__all__ = ["Struct", "class_of_struct", "struct"]
