"""Vector, matrix and struct values held as their parts (scalarized registers).

LLVM's loop vectorizer gives up on a loop whose body holds values of LLVM vector
type, so the cpu backend never makes any: a value of a vector, quaternion,
transform or matrix type is a ``Parts`` of one LLVM scalar per component
(matrices row-major), a struct value a ``Parts`` of its fields' values (scalars,
array descriptors, handles, or nested ``Parts``). Everything else is one LLVM
value, a *leaf*. Elementwise ops become one scalar op per component; the
vectorizers (loop and SLP) form wide instructions again where that pays.

Where a value must cross something that takes LLVM values only (phis, call
arguments and returns), it is flattened to its leaves and rebuilt from them.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from typing import Any

from llvmlite import ir

from kdsl.backends.cpu import types as LT
from kdsl.ir import types as T


class Parts:
    """The parts of one vector, matrix or struct value (see the module docstring)."""

    __slots__ = ("items",)

    def __init__(self, items: Iterable[Any]) -> None:
        self.items = list(items)

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, i: int) -> Any:
        return self.items[i]

    def __iter__(self) -> Iterator[Any]:
        return iter(self.items)

    def __repr__(self) -> str:
        return f"Parts({self.items!r})"


def is_composite(t: T.Type) -> bool:
    """True for the types whose values are ``Parts``."""
    return isinstance(t, T.VectorType | T.MatrixType | T.StructType)


def components(v: Any) -> list[Any]:
    """The components of a vector or matrix value, or ``[v]`` for a scalar."""
    return v.items if isinstance(v, Parts) else [v]


def leaves(v: Any) -> list[ir.Value]:
    """All LLVM values of ``v``, depth first (``[v]`` for a leaf)."""
    if not isinstance(v, Parts):
        return [v]
    return [leaf for item in v.items for leaf in leaves(item)]


def leaf_types(t: T.Type) -> list[ir.Type]:
    """The LLVM types of the leaves of a value of IR type ``t``, in ``leaves`` order."""
    if isinstance(t, T.VectorType | T.MatrixType):
        return [LT.scalar_type(t.elem)] * LT.count(t)
    if isinstance(t, T.StructType):
        return [lt for _, ft in t.fields for lt in leaf_types(ft)]
    return [LT.llvm_type(t)]


def rebuild(t: T.Type, vals: Iterator[ir.Value]) -> Any:
    """A value of IR type ``t`` from its leaves, consumed from ``vals`` in order."""
    if isinstance(t, T.VectorType | T.MatrixType):
        return Parts(next(vals) for _ in range(LT.count(t)))
    if isinstance(t, T.StructType):
        return Parts(rebuild(ft, vals) for _, ft in t.fields)
    return next(vals)


def rebuild_all(types: Iterable[T.Type], flat: Iterable[ir.Value]) -> list[Any]:
    """Values of ``types`` from their leaves concatenated (the inverse of flattening)."""
    it = iter(flat)
    out = [rebuild(t, it) for t in types]
    if next(it, None) is not None:
        raise ValueError("more leaves than the types hold")
    return out
