"""Warp 1.19's subscripted array types: ``array[vec3]``, ``array2d[float]``, ``array[float, 3]``.

``kdsl.array[dtype]`` (and ``array[dtype, ndim]``, ``array1d..array4d[dtype]``,
``indexedarray[dtype]``, ``indexedarray[dtype, ndim]``) gives an ``ArrayAnnotation``:
a small, hashable description of an array type that allocates nothing. It is
accepted everywhere ``array(dtype=..., ndim=...)`` is: kernel and function
annotations, struct fields, and from Python, where calling it builds an array of
that type (``kdsl.array[kdsl.vec3](points)``). ``ndim`` may be a plain int or
``typing.Literal[n]``, as in Warp.
"""

from __future__ import annotations

from typing import Any, Literal, get_args, get_origin

from kdsl.errors import KdslTypeError
from kdsl.ir import types as T
from kdsl.runtime.dtypes import resolve_dtype

#: The largest array rank kdsl (like Warp) supports.
MAX_DIMS = 4


class ArrayAnnotation:
    """The array type ``family[dtype, ndim]``; ``family`` is ``array`` or ``indexedarray``."""

    __slots__ = ("family", "dtype", "ndim")

    def __init__(self, family: type, dtype: Any, ndim: int) -> None:
        self.family = family
        self.dtype = dtype
        self.ndim = ndim

    @property
    def __kdsl_type__(self) -> T.Type:
        if self.dtype is Any:
            raise TypeError(f"{self!r} is generic: kernels need a concrete dtype")
        return self.family.annotation_type(self.dtype, self.ndim)

    @property
    def __kdsl_generic__(self) -> tuple | None:
        """For ``dtype=Any``: how to make the type per element type (``frontend.generic``)."""
        if self.dtype is not Any:
            return None
        family, ndim = self.family, self.ndim
        return (lambda dtype: family.annotation_type(dtype, ndim)), ndim

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        """An array of this type: ``array[vec3](data)`` is ``array(data, dtype=vec3, ndim=1)``."""
        kwargs.setdefault("ndim", self.ndim)
        if self.dtype is not Any:
            kwargs.setdefault("dtype", self.dtype)
        return self.family(*args, **kwargs)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, ArrayAnnotation):
            return NotImplemented
        return (self.family, self.dtype, self.ndim) == (other.family, other.dtype, other.ndim)

    def __hash__(self) -> int:
        return hash((self.family, self.dtype, self.ndim))

    def __repr__(self) -> str:
        dtype = "Any" if self.dtype is Any else getattr(self.dtype, "__name__", repr(self.dtype))
        name = self.family.__name__
        if name == "array" and self.ndim > 1:
            return f"array{self.ndim}d[{dtype}]"
        return f"{name}[{dtype}]" if self.ndim == 1 else f"{name}[{dtype}, {self.ndim}]"


def subscript(family: type, params: Any, ndim: int | None = None) -> ArrayAnnotation:
    """``family[params]``: ``params`` is a dtype, or ``(dtype, ndim)`` unless ``ndim`` is fixed.

    ``ndim`` is given by the fixed-rank spellings (``array2d[float]``), which take
    the dtype alone.
    """
    name = family.__name__ if ndim is None else f"{family.__name__}{ndim}d"
    if isinstance(params, tuple):
        if ndim is not None or len(params) != 2:
            expected = (
                "one type parameter (dtype)"
                if ndim is not None
                else "1 or 2 type parameters (dtype, ndim)"
            )
            raise KdslTypeError(f"{name}[...] expects {expected}, got {len(params)}")
        params, ndim = params[0], _rank(name, params[1])
    _check_dtype(name, params)
    return ArrayAnnotation(family, params, 1 if ndim is None else ndim)


def _rank(name: str, ndim: Any) -> int:
    if get_origin(ndim) is Literal:
        values = get_args(ndim)
        ndim = values[0] if len(values) == 1 else values
    if isinstance(ndim, bool) or not isinstance(ndim, int) or not 1 <= ndim <= MAX_DIMS:
        raise KdslTypeError(
            f"{name}[dtype, ndim]: ndim must be an integer from 1 to {MAX_DIMS} (or "
            f"Literal[n]), got {ndim!r}"
        )
    return ndim


def _check_dtype(name: str, dtype: Any) -> None:
    if dtype is Any:
        return
    try:
        resolve_dtype(dtype)
    except Exception as e:
        raise KdslTypeError(f"{name}[{getattr(dtype, '__name__', dtype)!s}]: {e}") from None
