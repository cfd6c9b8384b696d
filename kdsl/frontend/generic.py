"""Generic parameters: ``typing.Any`` and arrays with ``dtype=Any`` (Warp's generics).

A kernel or ``@kdsl.func`` with such a parameter is a family of instances, one per
tuple of concrete argument types. Its ``arg_types()`` hold a ``Generic`` at each
generic position; a call (``FunctionCompiler.pick_overload``) or a launch
(``kdsl.runtime.launch``) fills them in from the arguments and compiles the
instance for those types once (``CompileTarget.instance``).

An array annotation is generic when it offers ``__kdsl_generic__``: a pair
``(make, ndim)`` where ``make(dtype)`` is the IR type of that array family with
element type ``dtype`` (``kdsl.array[Any]``, ``kdsl.array(dtype=Any, ndim=2)``,
``kdsl.indexedarray[Any]`` do).
"""

from __future__ import annotations

import typing
from collections.abc import Callable
from typing import Any, TypeVar

from kdsl.frontend.structs import is_indexed
from kdsl.ir.types import F32, ArrayType, ScalarType, Type
from kdsl.types import Scalar


class Generic:
    """A parameter type filled in per call or launch: any value, or an array of any dtype."""

    def __init__(
        self,
        label: str,
        make: Callable[[Type], Type] | None = None,
        accept: Callable[[Type], bool] | None = None,
    ) -> None:
        self.label = label
        self.make = make
        self.accept = accept

    def matches(self, t: Type) -> bool:
        """Whether an argument of type ``t`` fits this parameter."""
        if self.make is not None:
            elem = element_type(t)
            return elem is not None and self.make(elem) == t
        return self.accept is None or self.accept(t)

    def __str__(self) -> str:
        return self.label

    __repr__ = __str__


#: ``typing.Any`` as a parameter type: any value type.
ANY = Generic("Any")

#: Warp's generic scalar annotations: ``wp.Float`` (any float type), ``wp.Int`` (any
#: integer type) and ``wp.Scalar`` (any number type), as in ``def f(x: wp.Float)``.
Float = TypeVar("Float")
Int = TypeVar("Int")


def _is_number(t: Type, kinds: str) -> bool:
    return isinstance(t, ScalarType) and t.kind in kinds.split()


_SCALAR_GENERICS = {
    Float: Generic("Float", accept=lambda t: _is_number(t, "float")),
    Int: Generic("Int", accept=lambda t: _is_number(t, "int uint")),
    Scalar: Generic("Scalar", accept=lambda t: _is_number(t, "float int uint")),
}


def element_type(t: Type) -> Type | None:
    """The element type of an array or indexed array type, else None."""
    if isinstance(t, ArrayType):
        return t.dtype
    if is_indexed(t):
        return t.fields[0][1].dtype
    return None


def generic_of(ann: Any) -> Generic | None:
    """The ``Generic`` an annotation names, or None for a concrete (or invalid) one."""
    if ann is typing.Any:
        return ANY
    if ann in _SCALAR_GENERICS:
        return _SCALAR_GENERICS[ann]
    spec = getattr(ann, "__kdsl_generic__", None)
    if spec is None:
        return None
    make, ndim = spec
    family = "indexedarray" if is_indexed(make(F32)) else "array"
    return Generic(f"{family}(dtype=Any, ndim={ndim})", make)


def is_generic(types: list[Any]) -> bool:
    """True when a parameter list holds a ``Generic``."""
    return any(isinstance(t, Generic) for t in types)
