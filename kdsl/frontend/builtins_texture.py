"""Warp 1.19's texture builtin: ``texture_sample(tex, uv, dtype=float, lod=-1.0)``.

The lowering checks the call at compile time (a texture record first, coordinates
that match its dimensions, a ``dtype`` of ``float``, ``vec2f`` or ``vec4f``, a float
``lod``) and calls the standard library's sampler (``kdsl.stdlib.texture``, handed
down through ``register_library``) with a zero of ``dtype`` as its witness. The
texture records are ``@kdsl.struct`` types of the standard library named
``Texture1D``, ``Texture2D`` and ``Texture3D``; this layer knows them by name only.
"""

from __future__ import annotations

from typing import Any

from kdsl.errors import KdslTypeError
from kdsl.frontend.builtins_base import BuiltinTable
from kdsl.frontend.library import library_function
from kdsl.frontend.values import describe, is_weak, named_type
from kdsl.ir import Value
from kdsl.ir.types import F32, ScalarType, StructType, Type, VectorType

TABLE = BuiltinTable(__name__)

#: Texture record struct names -> their dimensions.
RECORDS = {"Texture1D": 1, "Texture2D": 2, "Texture3D": 3}
#: What a sample can return: one, two or four channels.
SAMPLE_TYPES: tuple[Type, ...] = (F32, VectorType(2, F32), VectorType(4, F32))
#: The standard-library samplers, by dimensions (``kdsl.stdlib.api`` registers them).
LIBRARY = {1: "texture_sample_1d", 2: "texture_sample_2d", 3: "texture_sample_3d"}
_COORDS = {1: "u (a float)", 2: "uv (a vec2f) or u, v (two floats)",
           3: "uvw (a vec3f) or u, v, w (three floats)"}  # fmt: skip

DOC = (
    "``texture_sample(tex, uv, dtype=float, lod=-1.0)``: texture ``tex`` (a ``Texture1D``, "
    "``Texture2D`` or ``Texture3D``) sampled at ``uv``: ``u`` (a float) for 1-d, a vec2f "
    "or ``u, v`` for 2-d, a vec3f or ``u, v, w`` for 3-d, with the texture's filter "
    "and address modes (normalized coordinates put texel ``i``'s center at ``(i + 0.5) / "
    "size``, unnormalized ones at ``i + 0.5``). ``dtype`` (``float``, ``vec2f`` or "
    "``vec4f``) picks 1, 2 or 4 channels; channels the texture lacks read 0. 8/16-bit "
    "integer texels read normalized to [0, 1] (unsigned) or [-1, 1] (signed). ``lod`` "
    "picks the mip level (negative: level 0; fractional: a blend under ``LINEAR`` mip "
    "filtering). Sampled in software, in float32, the same on every backend. "
    "Differentiable in the coordinates and ``lod``."
)


def _is_dtype(x: Any) -> bool:
    """Whether the call argument ``x`` names a type (a ``dtype`` given by position)."""
    if isinstance(x, Value) or is_weak(x) or isinstance(x, tuple | list | str):
        return False
    return named_type(x) is not None


def _sample_type(em, dtype: Any, node) -> Type:
    t = named_type(dtype)
    if t not in SAMPLE_TYPES:
        got = t if t is not None else describe(dtype)
        raise em.error(KdslTypeError, f"texture_sample(): unsupported texture type {got}; "
                       "dtype is float, vec2f or vec4f (1, 2 or 4 channels)", node)  # fmt: skip
    return t


def _texture(em, tex: Any, node) -> tuple[Value, int]:
    t = tex.type if isinstance(tex, Value) else None
    if not isinstance(t, StructType) or t.name not in RECORDS:
        got = t if t is not None else describe(tex)
        raise em.error(KdslTypeError, "texture_sample(): the first argument must be a "
                       f"Texture1D, Texture2D or Texture3D, got {got}", node)  # fmt: skip
    return tex, RECORDS[t.name]


def _float(em, x: Any, what: str, node) -> Value:
    if is_weak(x) and not isinstance(x, bool):
        return em.value(x, node, want=F32)
    if isinstance(x, Value) and isinstance(x.type, ScalarType) and x.type.is_float:
        return x if x.type == F32 else em.emit_typed("arith.cast", [x], F32, node)
    if isinstance(x, Value) and isinstance(x.type, ScalarType) and x.type.is_int:
        return em.emit_typed("arith.cast", [x], F32, node)
    raise em.error(KdslTypeError, f"texture_sample(): {what} must be a float, got "
                   f"{describe(x)}", node)  # fmt: skip


def _coords(em, coords: list[Any], ndim: int, node) -> Value:
    """The coordinates as one float32 value (a scalar for 1-d, else a vector)."""
    one = coords[0] if len(coords) == 1 else None
    if ndim == 1 and one is not None and not isinstance(getattr(one, "type", None), VectorType):
        return _float(em, one, "u", node)
    if len(coords) == 1 and isinstance(coords[0], Value):
        t = coords[0].type
        if t == VectorType(ndim, F32):
            return coords[0]
    elif len(coords) == ndim and ndim > 1:
        parts = [_float(em, c, "uvw"[i], node) for i, c in enumerate(coords)]
        return em.emit_typed("vec.construct", parts, VectorType(ndim, F32), node)
    got = ", ".join(str(c.type) if isinstance(c, Value) else describe(c) for c in coords)
    raise em.error(KdslTypeError, f"texture_sample(): a {ndim}-d texture is sampled at "
                   f"{_COORDS[ndim]}, got ({got})", node)  # fmt: skip


@TABLE.define("texture_sample", (2, 6), DOC, "textures", ("dtype", "lod"))
def _texture_sample(em, args, node, **kwargs):
    tex, ndim = _texture(em, args[0], node)
    rest = list(args[1:])
    split = next((i for i, a in enumerate(rest) if _is_dtype(a)), None)
    coords = rest if split is None else rest[:split]
    tail = [] if split is None else rest[split:]
    if tail:
        if "dtype" in kwargs:
            raise em.error(KdslTypeError, "texture_sample() got dtype twice", node)
        kwargs["dtype"] = tail.pop(0)
    if tail:
        if "lod" in kwargs or len(tail) > 1:
            raise em.error(KdslTypeError, "texture_sample() takes (tex, coordinates, dtype, "
                           "lod): too many arguments", node)  # fmt: skip
        kwargs["lod"] = tail[0]
    if "dtype" not in kwargs:
        raise em.error(KdslTypeError, "texture_sample() needs the sample type: "
                       "texture_sample(tex, uv, dtype=float) (or wp.vec2f, wp.vec4f)",
                       node)  # fmt: skip
    like = em.zero(_sample_type(em, kwargs["dtype"], node), node)
    uv = _coords(em, coords, ndim, node)
    lod = _float(em, kwargs.get("lod", -1.0), "lod", node)
    return em.call_user(library_function(LIBRARY[ndim]), [tex, uv, lod, like], node)
