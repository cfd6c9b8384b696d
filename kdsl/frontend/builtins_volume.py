"""The volume builtins that take a value type: ``volume_sample(..., dtype=float)`` and kin.

Warp's ``volume_sample``, ``volume_sample_grad`` and ``volume_lookup`` take the grid's
value type as ``dtype=``, and ``volume_store``, ``volume_sample_index`` and
``volume_sample_grad_index`` work for any value type. Each lowering here checks the
types at compile time, with Warp's rules and messages (a supported value type, a
gradient of the matching shape, ``voxel_data`` and ``background`` of one type), then
calls the standard library's generic implementation (``kdsl.stdlib.volume``, handed
down through ``register_library``) with a zero of the value type as its witness.
"""

from __future__ import annotations

from typing import Any

from kdsl.errors import KdslTypeError
from kdsl.frontend.builtins_base import Builtin, BuiltinTable
from kdsl.frontend.library import library_function
from kdsl.frontend.values import describe, is_weak, named_type
from kdsl.ir import Value
from kdsl.ir.types import F32, F64, I32, I64, U32, ArrayType, MatrixType, Type, VectorType

TABLE = BuiltinTable(__name__)

#: Warp's volume value types.
VALUE_TYPES: tuple[Type, ...] = (
    I32, I64, U32, F32, F64, VectorType(3, F32), VectorType(3, F64), VectorType(4, F32),
    VectorType(4, F64),
)  # fmt: skip
_VEC3I = VectorType(3, I32)
_NAMES = "int32, int64, uint32, float32, float64, vec3f, vec3d, vec4f or vec4d"

#: The standard-library functions the lowerings call (``kdsl.stdlib.api`` registers them).
LIBRARY = (
    "volume_sample_value", "volume_sample_grad_value", "volume_lookup_value",
    "volume_store_value", "volume_sample_index_value", "volume_sample_grad_index_value",
)  # fmt: skip


def _value_type(em, t: Any, name: str, node) -> Type:
    """``t`` (a dtype or an IR type) if a volume can hold it."""
    ir_t = named_type(t)
    if ir_t not in VALUE_TYPES:
        got = ir_t if ir_t is not None else describe(t)
        raise em.error(KdslTypeError, f"{name}(): unsupported volume type {got}; a volume "
                       f"holds {_NAMES}", node)  # fmt: skip
    return ir_t


def grad_type(t: Type) -> Type:
    """The gradient of a value of type ``t`` by an index-space point: a 3-vector of its
    scalar type, or one row per component of a vector."""
    if isinstance(t, VectorType):
        return MatrixType(t.length, 3, t.elem)
    return VectorType(3, t)


def _check_grad(em, grad: Any, t: Type, name: str, node) -> Value:
    want = grad_type(t)
    if not isinstance(grad, Value) or grad.type != want:
        got = grad.type if isinstance(grad, Value) else describe(grad)
        raise em.error(KdslTypeError, f"{name}(): incompatible gradient type, expected {want}, "
                       f"got {got}", node)  # fmt: skip
    return grad


def _dtype(em, kwargs: dict, name: str, node, default: Any = None) -> Type:
    if "dtype" not in kwargs and default is None:
        raise em.error(KdslTypeError, f"{name}() needs the volume's value type: "
                       f"{name}(..., dtype=float)", node)  # fmt: skip
    return _value_type(em, kwargs.get("dtype", default), name, node)


def _call(em, name: str, args: list[Any], node) -> Any:
    return em.call_user(library_function(name), args, node)


def _define(name: str, arity: tuple[int, int], doc: str, keywords: tuple[str, ...] = (),
            inout: tuple[int, ...] = ()):  # fmt: skip
    def deco(lower):
        TABLE.add(Builtin(name, lower, doc, arity, "geometry", keywords, inout))
        return lower

    return deco


@_define("volume_sample", (3, 3), "``volume_sample(id, uvw, sampling_mode, dtype)``: the "
         "volume ``id`` (of values of type ``dtype``) sampled at index-space point ``uvw``: "
         "``CLOSEST`` gives the nearest voxel (halfway rounds away from zero), ``LINEAR`` "
         "trilinear interpolation, differentiable in ``uvw``. Zero for a volume of another "
         "value type (a debug build stops with an error).", ("dtype",))  # fmt: skip
def _volume_sample(em, args, node, **kwargs):
    t = _dtype(em, kwargs, "volume_sample", node)
    return _call(em, "volume_sample_value", [*args, em.zero(t, node)], node)


@_define("volume_sample_grad", (4, 4), "``volume_sample_grad(id, uvw, sampling_mode, grad, "
         "dtype)``: ``volume_sample``, and the sample's gradient by ``uvw`` written to "
         "``grad`` (a vec3 of the scalar type, or an N x 3 matrix for vectors; zero for "
         "``CLOSEST``).", ("dtype",), inout=(3,))  # fmt: skip
def _volume_sample_grad(em, args, node, **kwargs):
    t = _dtype(em, kwargs, "volume_sample_grad", node)
    _check_grad(em, args[3], t, "volume_sample_grad", node)
    return _call(em, "volume_sample_grad_value", [*args, em.zero(t, node)], node)


def _voxel(em, args: list[Any], name: str, node) -> list[Any]:
    """The voxel arguments of a lookup or store: ``[i, j, k]``, or ``[ijk]`` (a vec3i, the
    seeds' ``volume_lookup(vol, ijk)``)."""

    def fits(a: Any, t: Type) -> bool:
        if isinstance(a, Value):
            return a.type == t
        return t == I32 and isinstance(a, int) and not isinstance(a, bool)

    want = [I32] * 3 if len(args) == 3 else [_VEC3I] if len(args) == 1 else None
    if want is None:
        got = f"{len(args)} arguments"
    elif all(fits(a, t) for a, t in zip(args, want)):
        return args
    else:
        got = "(" + ", ".join(str(a.type) if isinstance(a, Value) else repr(a) for a in args) + ")"
    raise em.error(KdslTypeError, f"{name}(): a voxel is a vec3i or three int32s (i, j, k), "
                   f"got {got}", node)  # fmt: skip


@_define("volume_lookup", (2, 4), "``volume_lookup(id, i, j, k, dtype=float)``: the value "
         "(of type ``dtype``) of voxel ``(i, j, k)``: its leaf's, its tile's or the "
         "background. ``volume_lookup(id, ijk, dtype=float)`` takes the voxel as a vec3i. "
         "Not differentiable.", ("dtype",))  # fmt: skip
def _volume_lookup(em, args, node, **kwargs):
    voxel = _voxel(em, args[1:], "volume_lookup", node)
    # ``dtype`` defaults to float32, as the seeds' older ``volume_lookup(vol, ijk)``.
    t = _dtype(em, kwargs, "volume_lookup", node, default=F32)
    return _call(em, "volume_lookup_value", [args[0], *voxel, em.zero(t, node)], node)


@_define("volume_store", (3, 5), "``volume_store(id, i, j, k, value)``: write ``value`` to "
         "voxel ``(i, j, k)`` when a leaf holds it and the volume holds values of its type "
         "(no voxel is allocated or activated). ``volume_store(id, ijk, value)`` takes the "
         "voxel as a vec3i. Not differentiable.")  # fmt: skip
def _volume_store(em, args, node):
    voxel = _voxel(em, args[1:-1], "volume_store", node)
    value = args[-1]
    if is_weak(value) and not isinstance(value, bool):
        value = em.value(value, node)
    t = _value_type(em, value.type if isinstance(value, Value) else value, "volume_store", node)
    return _call(em, "volume_store_value", [args[0], *voxel, em.value(value, node, want=t)],
                 node)  # fmt: skip


def _index_data(em, args, name: str, node) -> tuple[Value, Value, Type]:
    """``voxel_data`` and ``background`` of an index sampler, checked: one value type."""
    data = args[3]
    if not isinstance(data, Value) or not isinstance(data.type, ArrayType):
        raise em.error(KdslTypeError, f"{name}(): voxel_data must be an array, not "
                       f"{describe(data)}", node)  # fmt: skip
    t = _value_type(em, data.type.dtype, name, node)
    background = args[4]
    if is_weak(background):
        background = em.value(background, node, want=t)
    if not isinstance(background, Value) or background.type != t:
        got = background.type if isinstance(background, Value) else describe(background)
        raise em.error(KdslTypeError, f"{name}(): the voxel_data array ({t}) and the "
                       f"background value ({got}) must have the same dtype", node)  # fmt: skip
    return data, background, t


@_define("volume_sample_index", (5, 5), "``volume_sample_index(id, uvw, sampling_mode, "
         "voxel_data, background)``: ``volume_sample`` of the values in ``voxel_data`` (one "
         "per indexable voxel, ``volume_lookup_index``; ``background`` where a voxel has "
         "none). ``LINEAR`` is differentiable in ``uvw``, ``voxel_data`` and "
         "``background``.")  # fmt: skip
def _volume_sample_index(em, args, node):
    data, background, t = _index_data(em, args, "volume_sample_index", node)
    return _call(em, "volume_sample_index_value",
                 [*args[:3], data, background, em.zero(t, node)], node)  # fmt: skip


@_define("volume_sample_grad_index", (6, 6), "``volume_sample_grad_index(id, uvw, "
         "sampling_mode, voxel_data, background, grad)``: ``volume_sample_index``, and the "
         "sample's gradient by ``uvw`` written to ``grad``.", inout=(5,))  # fmt: skip
def _volume_sample_grad_index(em, args, node):
    data, background, t = _index_data(em, args, "volume_sample_grad_index", node)
    grad = _check_grad(em, args[5], t, "volume_sample_grad_index", node)
    return _call(em, "volume_sample_grad_index_value",
                 [*args[:3], data, background, grad, em.zero(t, node)], node)  # fmt: skip
