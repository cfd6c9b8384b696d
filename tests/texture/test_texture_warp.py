"""kdsl's textures beside Warp 1.19's on Warp's CPU device (software sampling there too):
the same data, modes and coordinates give the same samples, for every texel format,
address mode, filter mode, coordinate kind, mip filter and dimension, and the same
mip chains. Skips without warp-lang (the ``bench`` extra)."""

import numpy as np
import pytest

import kdsl as wp
from tests.warp_peer import import_warp_cpu

warp = import_warp_cpu()

COORDS = {1: "float", 2: "vec2", 3: "vec3"}


def _kernels(m):
    @m.kernel
    def s1(t: m.Texture1D, uv: m.array(dtype=float), lod: float, out: m.array(dtype=m.vec4)):
        i = m.tid()
        out[i] = m.texture_sample(t, uv[i], dtype=m.vec4, lod=lod)

    @m.kernel
    def s2(t: m.Texture2D, uv: m.array(dtype=m.vec2), lod: float, out: m.array(dtype=m.vec4)):
        i = m.tid()
        out[i] = m.texture_sample(t, uv[i], dtype=m.vec4, lod=lod)

    @m.kernel
    def s3(t: m.Texture3D, uv: m.array(dtype=m.vec3), lod: float, out: m.array(dtype=m.vec4)):
        i = m.tid()
        out[i] = m.texture_sample(t, uv[i], dtype=m.vec4, lod=lod)

    return {1: (m.Texture1D, s1, float), 2: (m.Texture2D, s2, m.vec2),
            3: (m.Texture3D, s3, m.vec3)}  # fmt: skip


KDSL, WARP = _kernels(wp), _kernels(warp)


def _both(ndim, data, uv, lod, **modes):
    out = []
    for m, kernels in ((wp, KDSL), (warp, WARP)):
        cls, kernel, coord = kernels[ndim]
        tex = cls(data, device="cpu", **modes)
        res = m.zeros(len(uv), dtype=m.vec4, device="cpu")
        m.launch(kernel, len(uv), inputs=[tex, m.array(uv, dtype=coord, device="cpu"), lod, res],
                 device="cpu")  # fmt: skip
        out.append(res.numpy())
    return out


def _data(rng, shape, fmt):
    if np.issubdtype(fmt, np.integer):
        info = np.iinfo(fmt)
        return rng.integers(info.min, info.max, shape, endpoint=True).astype(fmt)
    return (rng.standard_normal(shape) * 2).astype(fmt)


FORMATS = [np.uint8, np.uint16, np.int8, np.int16, np.float16, np.float32, np.uint32, np.int32]


@pytest.mark.parametrize("ndim", [1, 2, 3])
@pytest.mark.parametrize("fmt", FORMATS, ids=lambda f: np.dtype(f).name)
def test_samples_equal_warps_on_the_cpu(ndim, fmt):
    rng = np.random.default_rng(ndim)
    shape = {1: (9,), 2: (6, 9), 3: (4, 6, 5)}[ndim]
    channels = {1: 4, 2: 2, 3: 1}[ndim]
    data = _data(rng, shape + ((channels,) if channels > 1 else ()), fmt)
    integer32 = np.dtype(fmt).itemsize == 4 and np.issubdtype(fmt, np.integer)
    worst = 0.0
    for filter_mode in [0] if integer32 else [0, 1]:
        for mode in range(4):
            for normalized in (True, False):
                uv = rng.uniform(-1.4, 2.3, (50, ndim)).astype(np.float32)
                if not normalized:
                    uv *= np.array(shape[::-1][:ndim], np.float32)
                uv = uv[:, 0].copy() if ndim == 1 else uv
                for mips, lod, mip_filter in ((1, -1.0, 1), (0, 1.4, 0 if integer32 else 1),
                                              (0, 0.6, 0)):
                    modes = {"filter_mode": filter_mode, "address_mode": mode,
                             "normalized_coords": normalized, "num_mip_levels": mips,
                             "mip_filter_mode": mip_filter}  # fmt: skip
                    ours, theirs = _both(ndim, data, uv, lod, **modes)
                    scale = max(1.0, float(np.abs(theirs).max()))
                    worst = max(worst, float(np.abs(ours - theirs).max()) / scale)
    assert worst <= 1e-6, worst


def test_per_axis_modes_equal_warps():
    rng = np.random.default_rng(9)
    data = rng.random((4, 5, 6, 4), dtype=np.float32)
    uv = rng.uniform(-1.5, 2.5, (100, 3)).astype(np.float32)
    for modes in ((0, 2, 3), (3, 1, 0), (2, 2, 1)):
        ours, theirs = _both(3, data, uv, -1.0, address_mode=modes)
        np.testing.assert_allclose(ours, theirs, rtol=1e-6, atol=1e-6)


def test_properties_equal_warps():
    data = np.zeros((8, 16, 2), np.uint16)
    ours = wp.Texture2D(data, num_mip_levels=0, address_mode_v=wp.TextureAddressMode.WRAP,
                        device="cpu")  # fmt: skip
    theirs = warp.Texture2D(data, num_mip_levels=0, address_mode_v=warp.TextureAddressMode.WRAP,
                            device="cpu")  # fmt: skip
    for name in ("ndim", "width", "height", "depth", "num_channels", "filter_mode",
                 "mip_filter_mode", "num_mip_levels", "is_mipmapped", "address_mode_u",
                 "address_mode_v", "address_mode_w", "normalized_coords"):  # fmt: skip
        assert getattr(ours, name) == getattr(theirs, name), name
    assert ours.dtype.__name__ == theirs.dtype.__name__ == "uint16"
    for a, b in zip(wp.TextureAddressMode, warp.TextureAddressMode, strict=True):
        assert (a.name, int(a)) == (b.name, int(b))
    for a, b in zip(wp.TextureFilterMode, warp.TextureFilterMode, strict=True):
        assert (a.name, int(a)) == (b.name, int(b))
    for a, b in zip(wp.TextureResourceFlags, warp.TextureResourceFlags, strict=True):
        assert (a.name, int(a)) == (b.name, int(b))
