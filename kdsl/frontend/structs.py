"""Structs in kernels: construction, zero values, the module's struct table, and
indexed arrays (whose kernel type is a struct, see ``indexed_type``).

``@kdsl.struct`` itself and struct values in Python scope live in
``kdsl.runtime.structs``; kernels see only the IR ``StructType``: ``Particle()``
zero-constructs, ``Particle(m=1.0, ...)`` sets fields by keyword (or position),
``p.x`` reads and ``p.x = v`` assigns (a new SSA value).
"""

from __future__ import annotations

import ast
from functools import cache
from typing import Any

from kdsl.errors import KdslTypeError
from kdsl.ir import Module
from kdsl.ir.types import I32, ArrayType, StructType, Type

#: Name prefix of the struct types that stand for indexed arrays.
INDEXED_PREFIX = "indexedarray_"


@cache
def indexed_type(dtype: Type, ndim: int) -> StructType:
    """The kernel type of an ``ndim``-d ``kdsl.indexedarray`` of ``dtype``.

    A struct holding the data array, one int32 index array per dimension (empty where
    the dimension is not indexed) and the view's shape; ``indexed_element`` lowers
    ``a[i, j]`` to loads of the index arrays and the data, so every backend runs it.
    """
    fields: list[tuple[str, Type]] = [("data", ArrayType(dtype, ndim))]
    fields += [(f"idx{k}", ArrayType(I32, 1)) for k in range(ndim)]
    fields += [(f"shape{k}", I32) for k in range(ndim)]
    flat = str(dtype).replace("<", "_").replace(">", "").replace(", ", "_")
    return StructType(f"{INDEXED_PREFIX}{flat}_{ndim}d", tuple(fields))


def is_indexed(t: Type) -> bool:
    """True for the struct types of indexed arrays."""
    return isinstance(t, StructType) and t.name.startswith(INDEXED_PREFIX)


# --- kernels --------------------------------------------------------------------------


def construct(em: Any, t: StructType, args: list[Any], kwargs: dict[str, Any], node: ast.AST):
    """``S(...)`` in a kernel: fields by position then keyword, the rest zero."""
    names = [n for n, _ in t.fields]
    if len(args) > len(names):
        raise em.error(KdslTypeError, f"{t.name}() takes at most {len(names)} field values, "
                       f"got {len(args)}", node)  # fmt: skip
    given = dict(zip(names, args))
    for k, v in kwargs.items():
        if k in given:
            raise em.error(KdslTypeError, f"{t.name}() got field '{k}' twice", node)
        given[k] = v
    parts = []
    for name, ft in t.fields:
        if name not in given:
            parts.append(zero_value(em, ft, node, f"{t.name}.{name}"))
            continue
        v = em.value(given[name], node, want=ft)
        if v.type != ft:
            raise em.error(KdslTypeError, f"field '{name}' of struct {t.name} is a {ft}, "
                           f"not a {v.type}", node)  # fmt: skip
        parts.append(v)
    return em.emit_typed("struct.construct", parts, t, node)


def has_zero(t: Type) -> bool:
    """Whether ``t`` has a zero value in a kernel (no array anywhere inside)."""
    if isinstance(t, ArrayType):
        return False
    return not isinstance(t, StructType) or all(has_zero(ft) for _, ft in t.fields)


def zero_value(em: Any, t: Type, node: ast.AST, what: str):
    """A zero value of ``t`` (structs field by field); arrays have none."""
    if isinstance(t, StructType):
        parts = [zero_value(em, ft, node, f"{what}.{n}") for n, ft in t.fields]
        return em.emit_typed("struct.construct", parts, t, node)
    if isinstance(t, ArrayType):
        raise em.error(KdslTypeError, f"{what} is an array and has no zero value in a kernel; "
                       "pass it to the constructor by keyword", node)  # fmt: skip
    return em.zero(t, node)


def register_structs(module: Module) -> None:
    """Add every struct type ``module`` uses to ``module.structs`` (nested ones first)."""
    seen: set[StructType] = set()

    def add(t: Type) -> None:
        if isinstance(t, ArrayType):
            add(t.dtype)
        elif isinstance(t, StructType) and t not in seen:
            seen.add(t)
            for _, ft in t.fields:
                add(ft)
            module.add_struct(t)

    for op in module.walk():
        for v in op.results:
            add(v.type)
        for v in op.operands:
            add(v.type)
        for region in op.regions:
            for a in region.block.args:
                add(a.type)
    for f in module.funcs:
        for t in f.attrs.get("res_types", []):
            add(t)


# --- indexed arrays: struct values lowered to plain loads ----------------------------


def indexed_shape(em: Any, v: Any, node: ast.AST) -> tuple:
    """``a.shape`` of an indexed array: its per-dimension lengths (a tuple of i32 values)."""
    nd = v.type.fields[0][1].ndim
    return tuple(em.emit("struct.extract", v, node=node, field=f"shape{k}") for k in range(nd))


def indexed_element(em: Any, v: Any, idx: list[Any], node: ast.AST) -> tuple:
    """(data array, data indices) of element ``idx`` of indexed array ``v``.

    Dimension ``k`` reads ``idx<k>[i]`` when its index array is not empty, else
    uses ``i`` (an indexed dimension with no indices has length 0, so any
    in-bounds access there has an index array to read).
    """
    data = em.emit("struct.extract", v, node=node, field="data")
    nd = data.type.ndim
    if len(idx) != nd:
        raise em.error(KdslTypeError, f"a {nd}-d indexed array needs {nd} indices, got "
                       f"{len(idx)}", node)  # fmt: skip
    out = []
    for k, i in enumerate(em.indices(data, idx, node)):
        if i.type != I32:
            i = em.emit_typed("arith.cast", [i], I32, node)
        ix = em.emit("struct.extract", v, node=node, field=f"idx{k}")
        n = em.emit("kd.array_shape", ix, node=node, dim=0)
        cond = em.emit("arith.cmp", n, em.zero(I32, node), node=node, pred="gt")
        out.append(em.if_value(cond, lambda ix=ix, i=i: em.emit("kd.load", ix, i, node=node),
                               lambda i=i: i, node, I32))  # fmt: skip
    return data, out
