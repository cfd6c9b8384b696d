"""A NumPy float64 reference of texture sampling, written from the documented semantics
(docs/language.md, "Textures"), independent of kdsl's sampler.

Texels are a ``(depth, height, width, channels)`` array of decoded float64 values per
mip level; coordinates are ``(n, ndim)`` arrays (u, v, w).
"""

from __future__ import annotations

import numpy as np

WRAP, CLAMP, MIRROR, BORDER = 0, 1, 2, 3
CLOSEST, LINEAR = 0, 1


def decode(texels: np.ndarray) -> np.ndarray:
    """Texel values as read: unsigned 8/16-bit to [0, 1], signed to [-1, 1], others as
    numbers."""
    x = texels.astype(np.float64)
    if texels.dtype == np.uint8:
        return x / 255
    if texels.dtype == np.uint16:
        return x / 65535
    if texels.dtype == np.int8:
        return np.maximum(x / 127, -1)
    if texels.dtype == np.int16:
        return np.maximum(x / 32767, -1)
    return x


def _map(i: np.ndarray, size: int, mode: int) -> tuple[np.ndarray, np.ndarray]:
    """(index into the axis, whether it reads a texel) of integer texel indices ``i``."""
    if mode == WRAP:
        return np.mod(i, size), np.ones(i.shape, bool)
    if mode == MIRROR:
        m = np.mod(i, 2 * size)
        return np.where(m < size, m, 2 * size - 1 - m), np.ones(i.shape, bool)
    if mode == CLAMP:
        return np.clip(i, 0, size - 1), np.ones(i.shape, bool)
    inside = (i >= 0) & (i < size)
    return np.where(inside, i, 0), inside


def _texel_coord(u: np.ndarray, base: int, size: int, mode: int, normalized: bool):
    """The coordinate in texel units of level ``size`` (one period for WRAP/MIRROR)."""
    u = u.astype(np.float64)
    if mode in (WRAP, MIRROR):
        period = (1.0 if normalized else base) * (2 if mode == MIRROR else 1)
        u = np.fmod(u, period)
    return u * size if normalized else u * size / base


def sample_level(level: np.ndarray, uvw: np.ndarray, base: tuple, modes: tuple,
                 filter_mode: int, normalized: bool) -> np.ndarray:  # fmt: skip
    """Samples (n, channels) of one decoded level."""
    ndim = uvw.shape[1]
    sizes = (level.shape[2], level.shape[1], level.shape[0])[:ndim]
    corners = []  # per axis: [(index, inside, weight), ...]
    for a in range(ndim):
        t = _texel_coord(uvw[:, a], base[a], sizes[a], modes[a], normalized)
        if filter_mode == CLOSEST:
            i, ok = _map(np.floor(t).astype(np.int64), sizes[a], modes[a])
            corners.append([(i, ok, np.ones(len(t)))])
            continue
        if modes[a] in (WRAP, MIRROR):
            t = np.where(t < 0, t + (2 if modes[a] == MIRROR else 1) * sizes[a], t)
        t = t - 0.5
        if modes[a] == CLAMP:
            t = np.clip(t, 0, sizes[a] - 1)
        lo = np.floor(t)
        f = t - lo
        i0, ok0 = _map(lo.astype(np.int64), sizes[a], modes[a])
        i1, ok1 = _map(lo.astype(np.int64) + 1, sizes[a], modes[a])
        corners.append([(i0, ok0, 1 - f), (i1, ok1, f)])
    while len(corners) < 3:
        corners.append([(np.zeros(len(uvw), np.int64), np.ones(len(uvw), bool), 1.0)])
    out = np.zeros((len(uvw), level.shape[3]))
    for x, okx, wx in corners[0]:
        for y, oky, wy in corners[1]:
            for z, okz, wz in corners[2]:
                w = np.asarray(wx * wy * wz * (okx & oky & okz))[:, None]
                out += w * level[z, y, x]
    return out


def sample(levels: list[np.ndarray], uvw: np.ndarray, modes: tuple, filter_mode: int,
           normalized: bool, lod: float = -1.0, mip_filter_mode: int = LINEAR,
           channels: int = 4) -> np.ndarray:  # fmt: skip
    """Samples (n, channels) of the decoded mip ``levels``; channels the texture lacks
    read zero."""
    ndim = uvw.shape[1]
    base = (levels[0].shape[2], levels[0].shape[1], levels[0].shape[0])[:ndim]

    def at(m: int) -> np.ndarray:
        return sample_level(levels[m], uvw, base, modes, filter_mode, normalized)

    top = len(levels) - 1
    if lod < 0 or top == 0:
        got = at(0)
    elif mip_filter_mode == CLOSEST:
        got = at(min(int(np.floor(min(lod, top) + 0.5)), top))
    else:
        lod = min(lod, top)
        m0 = int(np.floor(lod))
        got = at(m0) if m0 == top else (1 - (lod - m0)) * at(m0) + (lod - m0) * at(m0 + 1)
    out = np.zeros((len(uvw), channels))
    n = min(channels, got.shape[1])
    out[:, :n] = got[:, :n]
    return out


def box_levels(texels: np.ndarray, ndim: int, count: int) -> list[np.ndarray]:
    """Mip levels of a ``(d, h, w, c)`` array by a 2x box filter (pairs averaged; integer
    texels rounded back), ``count`` levels in all."""
    levels = [texels]
    for _ in range(count - 1):
        x = levels[-1].astype(np.float64)
        for axis in (2, 1, 0)[:ndim]:
            n = max(1, x.shape[axis] // 2)
            if n != x.shape[axis]:
                even = np.take(x, 2 * np.arange(n), axis=axis)
                odd = np.take(x, 2 * np.arange(n) + 1, axis=axis)
                x = (even + odd) / 2
        if np.issubdtype(texels.dtype, np.integer):
            info = np.iinfo(texels.dtype)
            x = np.clip(np.rint(x), info.min, info.max)
        levels.append(x.astype(texels.dtype))
    return levels
