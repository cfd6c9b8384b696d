"""kdsl standard library: texture sampling (Warp 1.19's ``texture_sample``), in kdsl.

A ``kdsl.Texture1D``/``2D``/``3D`` reaches a kernel as a record (the struct types
``Texture1D``, ``Texture2D`` and ``Texture3D`` below, which ``kdsl.texture`` fills):
its texels, its size, and the modes it was made with. Sampling is kdsl code, so every
backend (interp, cpu, cuda) gives the same result from the same source; kdsl uses no
hardware texture unit.

**Texels.** All mip levels, level 0 first, each laid out as NumPy's ``(depth, height,
width, channels)``, sit in one flat buffer of the texel format's width, reached through
one of three views (``texels8``, ``texels16``, ``texels32``; the other two are empty):
``uint8`` and ``int8`` texels through the 8-bit view, ``uint16``, ``int16`` and
``float16`` through the 16-bit one, ``float32``, ``uint32`` and ``int32`` through the
32-bit one (``wp.cast`` gives back the signed or float bits). A texel reads as float32
with Warp's rules: unsigned 8/16-bit integers divided by 255 or 65535 (range [0, 1]),
signed ones by 127 or 32767 and clamped at -1, 32-bit integers converted as numbers,
floats as they are.

**Coordinates.** With normalized coordinates, texel ``i`` of a level ``size`` texels
wide has its center at ``(i + 0.5) / size``; without, at ``i + 0.5`` (on level 0; a
coarser level scales by ``size / base_size``). ``WRAP`` and ``MIRROR`` first reduce the
coordinate to one period (1 or 2 normalized, the base size or twice it in texels).
``CLOSEST`` takes the texel whose cell holds the coordinate (computed in float64, as
Warp's CPU sampler); ``LINEAR`` blends the two (four, eight) nearest texel centers with
float32 weights, one axis after the other (u, then v, then w), in Warp's CPU order.
Indices beyond the edge wrap, mirror (``-1`` is ``0``), clamp, or read zero (``BORDER``).

**Mip levels.** ``lod < 0`` (the default) samples level 0; otherwise ``lod`` is clamped
to ``[0, num_mip_levels - 1]``, and ``mip_filter_mode`` picks the nearest level
(``CLOSEST``) or blends the two around it (``LINEAR``).

**Channels.** The witness ``like`` (a zero of ``float32``, ``vec2f`` or ``vec4f``, which
the ``dtype=`` of the builtin gives) says how many channels a sample returns; a channel
the texture lacks reads zero, as in Warp's CPU sampler.

Sampling is differentiable in the coordinates (and in ``lod`` between two mip levels
with ``LINEAR`` mip filtering): ``CLOSEST`` has a zero gradient, clamped coordinates
too. Texel data get no gradient, as in Warp.
"""

from typing import Any

import kdsl as wp
from kdsl.frontend.kernel import func

__kdsl_group__ = "textures"

__all__: list[str] = []

#: Warp's texel format codes (``WP_TEXTURE_DTYPE_*``).
UINT8, UINT16, FLOAT32, INT8, INT16, FLOAT16, UINT32, INT32 = 0, 1, 2, 3, 4, 5, 6, 7
#: Warp's filter modes (``TextureFilterMode``).
CLOSEST, LINEAR = 0, 1
#: Warp's address modes (``TextureAddressMode``).
WRAP, CLAMP, MIRROR, BORDER = 0, 1, 2, 3


def _record(ndim: int) -> Any:
    """The record struct ``Texture<ndim>D``: the texel views, the size along each axis
    (``width``, ``height``, ``depth``), the format and modes, an address mode per axis."""
    fields = {"texels8": wp.array(dtype=wp.uint8), "texels16": wp.array(dtype=wp.uint16),
              "texels32": wp.array(dtype=wp.uint32)}  # fmt: skip
    fields.update(dict.fromkeys(("width", "height", "depth")[:ndim], wp.int32))
    for name in ("num_channels", "texel_format", "texel_sign", "texel_scale", "filter_mode",
                 "mip_filter_mode", "num_mip_levels", "normalized"):  # fmt: skip
        fields[name] = wp.float32 if name == "texel_scale" else wp.int32
    fields.update({f"address_mode_{axis}": wp.int32 for axis in "uvw"[:ndim]})
    doc = f"The record of a ``kdsl.Texture{ndim}D`` (see the module docstring)."
    cls = type(f"Texture{ndim}D", (), {"__annotations__": fields, "__doc__": doc,
                                       "__module__": __name__})  # fmt: skip
    return wp.struct(cls)


Texture1D = _record(1)
Texture2D = _record(2)
Texture3D = _record(3)


# -- texels ----------------------------------------------------------------------------


@func
def _decode(rec: Any, k: int) -> float:
    """Element ``k`` of the texel buffer as float32, with Warp's normalization: 8- and
    16-bit integers sign-extended by ``texel_sign`` (their sign bit; 0 when unsigned),
    divided by ``texel_scale`` and clamped at -1."""
    fmt = rec.texel_format
    v = 0
    if fmt == UINT8 or fmt == INT8:  # noqa: SIM109 - kernels have no `in`
        v = int(rec.texels8[k])
    elif fmt == UINT16 or fmt == INT16:  # noqa: SIM109
        v = int(rec.texels16[k])
    elif fmt == FLOAT16:
        return float(wp.cast(rec.texels16[k], wp.float16))
    elif fmt == FLOAT32:
        return wp.cast(rec.texels32[k], wp.float32)
    elif fmt == UINT32:
        return float(rec.texels32[k])
    else:
        return float(wp.cast(rec.texels32[k], wp.int32))
    v = v - ((v & rec.texel_sign) << 1)
    return wp.max(float(v) / rec.texel_scale, -1.0)


@func
def _texel(rec: Any, n: int, like: wp.float32) -> wp.float32:
    """Texel ``n`` (counted over all levels), channel 0."""
    return _decode(rec, n * rec.num_channels)


@func
def _texel(rec: Any, n: int, like: wp.vec2) -> wp.vec2:
    """Texel ``n``, channels 0 and 1 (zero where the texture has one channel)."""
    k = n * rec.num_channels
    out = like
    for c in range(wp.min(rec.num_channels, 2)):
        out[c] = _decode(rec, k + c)
    return out


@func
def _texel(rec: Any, n: int, like: wp.vec4) -> wp.vec4:
    """Texel ``n``, channels 0 to 3 (zero where the texture has fewer)."""
    k = n * rec.num_channels
    out = like
    for c in range(rec.num_channels):
        out[c] = _decode(rec, k + c)
    return out


# -- one axis --------------------------------------------------------------------------


@func
def _level_size(base: int, level: int) -> int:
    return wp.max(base >> level, 1)


@func
def _periodic(mode: int) -> bool:
    if mode == WRAP:
        return True
    return mode == MIRROR


@func
def _period(base: int, mode: int, normalized: int) -> float:
    """The period ``WRAP`` or ``MIRROR`` reduces a coordinate by."""
    p = 1.0
    if normalized == 0:
        p = float(base)
    if mode == MIRROR:
        p = p * 2.0
    return p


@func
def _address(i: int, size: int, mode: int) -> int:
    """Index ``i`` of an axis ``size`` texels long under address mode ``mode`` (``BORDER``
    leaves it as it is: the caller reads zero outside)."""
    j = i
    if mode == WRAP:
        j = i % size
        if j < 0:
            j = j + size
    elif mode == MIRROR:
        p = 2 * size
        j = i % p
        if j < 0:
            j = j + p
        if j >= size:
            j = p - j - 1
    elif mode == CLAMP:
        j = wp.clamp(i, 0, size - 1)
    return j


@func
def _nearest(u: float, base: int, size: int, mode: int, normalized: int) -> int:
    """The texel index ``CLOSEST`` reads on an axis ``size`` texels long (``base`` on
    level 0): the cell holding ``u``, computed in float64."""
    r = wp.float64(u)
    if _periodic(mode):
        r = wp.mod(r, wp.float64(_period(base, mode, normalized)))
    t = r * wp.float64(size)
    if normalized == 0:
        t = t / wp.float64(base)
    if not _periodic(mode):
        t = wp.clamp(t, wp.float64(-1.0), wp.float64(size))
    return _address(int(wp.floor(t)), size, mode)


@func
def _linear(u: float, base: int, size: int, mode: int, normalized: int):
    """``(i0, i1, f)``: the texels ``LINEAR`` blends on an axis and the weight of ``i1``."""
    r = u
    if _periodic(mode):
        p = _period(base, mode, normalized)
        r = wp.mod(u, p)
        if r < 0.0:
            r = r + p
    if normalized == 0:
        r = r / float(base)
    t = r * float(size) - 0.5
    if mode == CLAMP:
        t = wp.clamp(t, 0.0, float(size - 1))
    elif mode == BORDER:
        t = wp.clamp(t, -2.0, float(size))  # both neighbours stay outside, ints stay small
    lo = wp.floor(t)
    i0 = int(lo)
    return _address(i0, size, mode), _address(i0 + 1, size, mode), t - lo


@func
def _inside(i: int, size: int) -> bool:
    return i >= 0 and i < size


# -- one level -------------------------------------------------------------------------


@func
def _level_start(rec: Texture1D, level: int) -> int:
    """The first texel of mip level ``level``."""
    start = 0
    for m in range(level):
        start = start + _level_size(rec.width, m)
    return start


@func
def _level_start(rec: Texture2D, level: int) -> int:
    start = 0
    for m in range(level):
        start = start + _level_size(rec.width, m) * _level_size(rec.height, m)
    return start


@func
def _level_start(rec: Texture3D, level: int) -> int:
    start = 0
    for m in range(level):
        plane = _level_size(rec.width, m) * _level_size(rec.height, m)
        start = start + plane * _level_size(rec.depth, m)
    return start


@func
def _fetch(rec: Any, n: int, inside: bool, like: Any):
    """Texel ``n``, or zero outside the texture (``BORDER``)."""
    if inside:
        return _texel(rec, n, like)
    return like


@func
def _bilinear(rec: Any, row0: int, row1: int, in0: bool, in1: bool, x0: int, x1: int, w: int,
              fx: float, fy: float, like: Any):  # fmt: skip
    """The blend of texels ``x0``, ``x1`` of the rows starting at ``row0`` and ``row1``
    (``in0``/``in1``: whether each row is inside the texture) by weights ``fx``, ``fy``."""
    v00 = _fetch(rec, row0 + x0, in0 and _inside(x0, w), like)
    v10 = _fetch(rec, row0 + x1, in0 and _inside(x1, w), like)
    v01 = _fetch(rec, row1 + x0, in1 and _inside(x0, w), like)
    v11 = _fetch(rec, row1 + x1, in1 and _inside(x1, w), like)
    a = v00 * (1.0 - fx) + v10 * fx
    b = v01 * (1.0 - fx) + v11 * fx
    return a * (1.0 - fy) + b * fy


@func
def _at_level(rec: Texture1D, level: int, u: float, like: Any):
    """The texture sampled on mip level ``level`` at ``u``."""
    w = _level_size(rec.width, level)
    start = _level_start(rec, level)
    mu = rec.address_mode_u
    if rec.filter_mode == CLOSEST:
        x = _nearest(u, rec.width, w, mu, rec.normalized)
        return _fetch(rec, start + x, _inside(x, w), like)
    x0, x1, fx = _linear(u, rec.width, w, mu, rec.normalized)
    v0 = _fetch(rec, start + x0, _inside(x0, w), like)
    v1 = _fetch(rec, start + x1, _inside(x1, w), like)
    return v0 * (1.0 - fx) + v1 * fx


@func
def _at_level(rec: Texture2D, level: int, uv: wp.vec2, like: Any):
    w = _level_size(rec.width, level)
    h = _level_size(rec.height, level)
    start = _level_start(rec, level)
    mu = rec.address_mode_u
    mv = rec.address_mode_v
    if rec.filter_mode == CLOSEST:
        x = _nearest(uv[0], rec.width, w, mu, rec.normalized)
        y = _nearest(uv[1], rec.height, h, mv, rec.normalized)
        return _fetch(rec, start + y * w + x, _inside(x, w) and _inside(y, h), like)
    x0, x1, fx = _linear(uv[0], rec.width, w, mu, rec.normalized)
    y0, y1, fy = _linear(uv[1], rec.height, h, mv, rec.normalized)
    return _bilinear(rec, start + y0 * w, start + y1 * w, _inside(y0, h), _inside(y1, h),
                     x0, x1, w, fx, fy, like)  # fmt: skip


@func
def _at_level(rec: Texture3D, level: int, uvw: wp.vec3, like: Any):
    w = _level_size(rec.width, level)
    h = _level_size(rec.height, level)
    d = _level_size(rec.depth, level)
    start = _level_start(rec, level)
    mu = rec.address_mode_u
    mv = rec.address_mode_v
    mw = rec.address_mode_w
    if rec.filter_mode == CLOSEST:
        x = _nearest(uvw[0], rec.width, w, mu, rec.normalized)
        y = _nearest(uvw[1], rec.height, h, mv, rec.normalized)
        z = _nearest(uvw[2], rec.depth, d, mw, rec.normalized)
        inside = _inside(x, w) and _inside(y, h) and _inside(z, d)
        return _fetch(rec, start + (z * h + y) * w + x, inside, like)
    x0, x1, fx = _linear(uvw[0], rec.width, w, mu, rec.normalized)
    y0, y1, fy = _linear(uvw[1], rec.height, h, mv, rec.normalized)
    z0, z1, fz = _linear(uvw[2], rec.depth, d, mw, rec.normalized)
    iny0 = _inside(y0, h)
    iny1 = _inside(y1, h)
    inz0 = _inside(z0, d)
    inz1 = _inside(z1, d)
    p0 = _bilinear(rec, start + (z0 * h + y0) * w, start + (z0 * h + y1) * w, inz0 and iny0,
                   inz0 and iny1, x0, x1, w, fx, fy, like)  # fmt: skip
    p1 = _bilinear(rec, start + (z1 * h + y0) * w, start + (z1 * h + y1) * w, inz1 and iny0,
                   inz1 and iny1, x0, x1, w, fx, fy, like)  # fmt: skip
    return p0 * (1.0 - fz) + p1 * fz


# -- mip levels ------------------------------------------------------------------------


@func
def _sample(rec: Any, coords: Any, lod: float, like: Any):
    """The texture sampled at ``coords`` with level of detail ``lod`` (see the module
    docstring)."""
    levels = rec.num_mip_levels
    level0 = 0
    level1 = 0
    f = 0.0
    if lod >= 0.0 and levels > 1:
        clamped = wp.min(lod, float(levels - 1))
        if rec.mip_filter_mode == CLOSEST:
            level0 = wp.min(int(wp.floor(clamped + 0.5)), levels - 1)
            level1 = level0
        else:
            lo = wp.floor(clamped)
            level0 = int(lo)
            level1 = wp.min(level0 + 1, levels - 1)
            f = clamped - lo
    v0 = _at_level(rec, level0, coords, like)
    if level1 == level0:
        return v0
    return v0 * (1.0 - f) + _at_level(rec, level1, coords, like) * f


@func
def texture_sample_1d(rec: Texture1D, u: float, lod: float, like: Any):
    """``texture_sample(tex, u, dtype=type(like), lod=lod)`` of a 1-d texture."""
    return _sample(rec, u, lod, like)


@func
def texture_sample_2d(rec: Texture2D, uv: wp.vec2, lod: float, like: Any):
    """``texture_sample(tex, uv, dtype=type(like), lod=lod)`` of a 2-d texture."""
    return _sample(rec, uv, lod, like)


@func
def texture_sample_3d(rec: Texture3D, uvw: wp.vec3, lod: float, like: Any):
    """``texture_sample(tex, uvw, dtype=type(like), lod=lod)`` of a 3-d texture."""
    return _sample(rec, uvw, lod, like)
