"""Warp's array builtins for kernels: ``view(arr, i...)`` and ``array(ptr, shape, dtype)``.

- ``view(arr, i, j=None, k=None, l=None)``: the sub-array at the leading indices, as
  ``arr[i]`` on a 2-d array gives (``kd.array_view``: it shares the memory).
- ``array(ptr=p, shape=(n, ...), dtype=T)``: a contiguous array over the memory at the
  ``uint64`` address ``p`` (``kd.array_from_ptr``); ``shape`` is an int or a tuple of 1
  to 4 ints (run-time values allowed), ``dtype`` a kdsl type. In Python scope
  ``kdsl.array`` is the array class, so the runtime hands it down once
  (``register_host_alias`` in ``kdsl.runtime.api``), as it does ``zeros``.
"""

from __future__ import annotations

from typing import Any

from kdsl.errors import KdslTypeError
from kdsl.frontend.builtins_base import Builtin, BuiltinTable
from kdsl.frontend.values import describe
from kdsl.ir import Value
from kdsl.ir.types import I32, U64, ArrayType, HandleType, Type
from kdsl.types import type_of

TABLE = BuiltinTable(__name__)


@TABLE.define(
    "view", (2, 5), "``view(arr, i...)``: the sub-array ``arr[i...]`` at fewer indices "
    "than ``arr`` has dims (it shares the memory), as Warp's.", "memory",
)  # fmt: skip
def _view(em, args, node):
    arr = em.value(args[0], node)
    if not isinstance(arr.type, ArrayType):
        raise em.error(KdslTypeError, f"view() needs an array first, not {arr.type}", node)
    idx = [a for a in args[1:] if a is not None]
    if len(idx) >= arr.type.ndim:
        raise em.error(
            KdslTypeError,
            f"view() of a {arr.type.ndim}-d array takes fewer than {arr.type.ndim} indices, "
            f"got {len(idx)}; index it (arr[i...]) for an element",
            node,
        )
    return em.emit("kd.array_view", arr, *em.indices(arr, idx, node), node=node)


def _array(em, args: list[Any], node, **kw: Any) -> Value:
    given = dict(zip(("ptr", "shape", "dtype"), args))
    if set(given) & set(kw):
        raise em.error(KdslTypeError, "array() got an argument twice", node)
    given.update(kw)
    missing = [k for k in ("ptr", "shape", "dtype") if k not in given]
    if missing:
        raise em.error(KdslTypeError, "array() in a kernel wraps memory at an address: "
                       f"array(ptr=..., shape=..., dtype=...) (missing {', '.join(missing)})",
                       node)  # fmt: skip
    ptr = em.value(given["ptr"], node, want=U64)
    if ptr.type != U64:
        raise em.error(KdslTypeError, f"array(): ptr must be a uint64 address, not {ptr.type}",
                       node)  # fmt: skip
    shape = given["shape"]
    dims = list(shape) if isinstance(shape, tuple | list) else [shape]
    if not 1 <= len(dims) <= 4:
        raise em.error(KdslTypeError, f"array(): shape has 1 to 4 dims, not {len(dims)}", node)
    extents = [em.value(d, node, want=I32) for d in dims]
    if any(not (e.type.is_scalar and e.type.is_int) for e in extents):
        raise em.error(KdslTypeError, "array(): shape holds integers", node)
    extents = [em.emit_typed("arith.cast", [e], I32, node) if e.type != I32 else e for e in extents]
    t = _dtype(em, given["dtype"], node)
    return em.emit_typed("kd.array_from_ptr", [ptr, *extents], ArrayType(t, len(dims)), node)


def _dtype(em, dtype: Any, node) -> Type:
    try:
        t = type_of(dtype)
    except (TypeError, KeyError):
        t = None
    if t is None or isinstance(t, ArrayType | HandleType):
        raise em.error(KdslTypeError, f"array(): dtype must be a kdsl value type, not "
                       f"{describe(dtype)}", node)  # fmt: skip
    return t


ARRAY_FROM_PTR = Builtin(
    "array",
    _array,
    "``array(ptr=p, shape=(n, ...), dtype=T)``: in a kernel, a contiguous array over the "
    "memory at the ``uint64`` address ``p`` (Warp's), with 1 to 4 run-time extents. Nothing "
    "is owned or checked: the memory must hold the elements while the array is used. In "
    "Python scope ``kdsl.array`` is the array class.",
    (0, 3),
    "memory",
    keywords=("ptr", "shape", "dtype"),
)
