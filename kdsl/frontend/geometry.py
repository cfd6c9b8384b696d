"""Quaternions and transforms in the kernel language: operators, parts, builtins.

The algebra itself is library code (``kdsl/stdlib/quat.py``, ``transform.py``);
this module connects Warp's spellings to it:

- ``q1 * q2`` (and ``mul(q1, q2)``) is the quaternion product and ``t1 * t2`` the
  transform composition (``binop``); scaling by a scalar, ``+``, ``-`` and unary
  ``-`` stay componentwise, as in Warp;
- ``t.p`` / ``t.q`` read a transform's translation and rotation, and ``t.p = v`` /
  ``t.q = q`` (also ``t.p += v``) replace them (``part``, ``with_part``);
- ``normalize(q)`` of a zero quaternion is the identity, as in Warp, and a zero vector
  stays zero (``normalize_quat``, which ``builtins_core``'s ``normalize`` asks first);
- the builtins ``quat_identity`` and ``transform_identity`` take a ``dtype``, and
  ``quaternion(...)`` / ``transformation(...)`` (type factories in Python scope)
  build values in kernels, as in Warp.
"""

from __future__ import annotations

import ast
from typing import Any

from kdsl import types as public
from kdsl.errors import KdslTypeError
from kdsl.frontend.builtins_base import BuiltinTable
from kdsl.frontend.library import library_function
from kdsl.frontend.values import is_weak
from kdsl.ir import Value
from kdsl.ir.types import (
    F32,
    MatrixType,
    QuatType,
    ScalarType,
    TransformType,
    Type,
    elem_type,
)

#: The parts of a transform by attribute name: the stdlib getter and copy-setter.
_PARTS = {
    "p": ("transform_get_translation", "transform_set_translation_copy"),
    "q": ("transform_get_rotation", "transform_set_rotation_copy"),
}

TABLE = BuiltinTable(__name__)


def binop(em, op: str, x: Value, y: Value, node: ast.AST) -> Value | None:
    """``x op y`` for quaternion and transform operands, or None for the generic rule."""
    geometric = (QuatType, TransformType)
    if not (isinstance(x.type, geometric) or isinstance(y.type, geometric)):
        return None
    if op in ("mul", "matmul") and (
        isinstance(x.type, MatrixType) or isinstance(y.type, MatrixType)
    ):
        raise em.error(KdslTypeError, f"cannot multiply {x.type} by {y.type}", node)
    if op != "mul" or x.type != y.type:
        return None  # componentwise (scaling, +, -) or a type error from the arith rule
    fn = "quat_multiply" if isinstance(x.type, QuatType) else "transform_multiply"
    return em.call_user(library_function(fn), [x, y], node)


def normalize_quat(em, x: Any, node: ast.AST) -> Value | None:
    """``normalize(x)`` for a quaternion ``x`` (a zero one gives the identity, as in Warp),
    or None for the generic rule (``vec.normalize``)."""
    if isinstance(x, Value) and isinstance(x.type, QuatType):
        return em.call_user(library_function("quat_normalize"), [x], node)
    return None


def has_part(t: Type, attr: str) -> bool:
    """True when ``t.attr`` is a transform part (``p`` or ``q``)."""
    return isinstance(t, TransformType) and attr in _PARTS


def part(em, v: Value, attr: str, node: ast.AST) -> Value:
    """``t.p`` (the translation) or ``t.q`` (the rotation) of transform ``v``."""
    return em.call_user(library_function(_PARTS[attr][0]), [v], node)


def with_part(em, v: Value, attr: str, value: Any, node: ast.AST) -> Value:
    """A copy of transform ``v`` with part ``attr`` replaced by ``value``."""
    return em.call_user(library_function(_PARTS[attr][1]), [v, value], node)


def _dtype_arg(em, args: list[Any], kwargs: dict[str, Any], node: ast.AST, name: str) -> ScalarType:
    if args and "dtype" in kwargs:
        raise em.error(KdslTypeError, f"{name}() got dtype twice", node)
    return _float_dtype(em, args[0] if args else kwargs.get("dtype"), node, name)


def _float_dtype(em, dtype: Any, node: ast.AST, name: str) -> ScalarType:
    """The float type ``dtype`` names (float32 when None), or a located error."""
    if dtype is None:
        return F32
    try:
        t = public.type_of(dtype)
    except TypeError:
        t = None
    if is_weak(dtype) or not (isinstance(t, ScalarType) and t.is_float):
        raise em.error(KdslTypeError, f"{name}() needs a float dtype such as wp.float64", node)
    return t


@TABLE.define("quat_identity", (0, 1), "``quat_identity(dtype=float32)``: the identity rotation "
              "(0, 0, 0, 1).", "quaternion", ("dtype",))  # fmt: skip
def _quat_identity(em, args, node, **kwargs):
    t = QuatType(_dtype_arg(em, args, kwargs, node, "quat_identity"))
    return em.construct(t, [0, 0, 0, 1], node)


@TABLE.define("transform_identity", (0, 1), "``transform_identity(dtype=float32)``: zero "
              "translation, identity rotation.", "transform", ("dtype",))  # fmt: skip
def _transform_identity(em, args, node, **kwargs):
    t = TransformType(_dtype_arg(em, args, kwargs, node, "transform_identity"))
    return em.construct(t, [0, 0, 0, 0, 0, 0, 1], node)


def _elem_of(em, args: list[Any], dtype: Any, node: ast.AST, name: str) -> ScalarType:
    # Warp's rule: an explicit dtype, else the first typed argument's, else float32.
    if dtype is not None:
        return _float_dtype(em, dtype, node, name)
    typed = next((a for a in args if isinstance(a, Value)), None)
    return elem_type(typed.type) if typed is not None else F32


@TABLE.define("quaternion", (0, 4), "``quaternion(x, y, z, w)``, ``quaternion(ijk, real)``, "
              "``quaternion(q)`` (a cast) or ``quaternion()`` (zeros), each with an optional "
              "``dtype=``.", "quaternion", ("dtype",))  # fmt: skip
def _quaternion(em, args, node, dtype=None):
    t = QuatType(_elem_of(em, args, dtype, node, "quaternion"))
    return em.construct(t, list(args), node)


@TABLE.define("transformation", (0, 7), "``transformation(p, q)``, ``transformation(p)`` "
              "(identity rotation), seven components, or ``transformation()`` (zeros), each with "
              "an optional ``dtype=``.", "transform", ("dtype",))  # fmt: skip
def _transformation(em, args, node, dtype=None):
    t = TransformType(_elem_of(em, args, dtype, node, "transformation"))
    args = list(args)
    if (
        len(args) == 1
        and isinstance(args[0], Value)
        and not isinstance(args[0].type, TransformType)
    ):
        args.append(em.construct(QuatType(t.elem), [0, 0, 0, 1], node))  # p alone
    return em.construct(t, args, node)


# ``wp.quaternion`` / ``wp.transformation`` are type factories in Python scope.
TABLE.alias(public.quaternion, "quaternion")
TABLE.alias(public.transformation, "transformation")
