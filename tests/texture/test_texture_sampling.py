"""``texture_sample`` (``kdsl.stdlib.texture``) against the NumPy float64 reference of
``texture_reference``: every address mode and filter mode, normalized and texel
coordinates, 1/2/4 channels read as float/vec2f/vec4f, every texel format, per-axis
address modes, mip levels with both mip filters, 1-d/2-d/3-d; on interp, cpu and cuda.
Also the uv/lod gradients (central differences) and the kernel-side ``tex.width``."""


import numpy as np
import pytest
from texture_reference import (
    BORDER,
    CLAMP,
    CLOSEST,
    LINEAR,
    MIRROR,
    WRAP,
    box_levels,
    decode,
    sample,
)

import kdsl as wp

cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")
BACKENDS = [("interp", "cpu"), ("cpu", "cpu"), pytest.param("cuda", "cuda:0", marks=cuda)]
TEXTURES = {1: wp.Texture1D, 2: wp.Texture2D, 3: wp.Texture3D}
COORDS = {1: float, 2: wp.vec2, 3: wp.vec3}


def _sampler(ndim: int, dtype):
    coord = COORDS[ndim]
    texture = TEXTURES[ndim]

    @wp.kernel
    def k(tex: texture, uv: wp.array(dtype=coord), lod: float,
          out: wp.array(dtype=dtype)):  # fmt: skip
        i = wp.tid()
        out[i] = wp.texture_sample(tex, uv[i], dtype=dtype, lod=lod)

    return k


SAMPLERS = {(n, d): _sampler(n, d) for n in (1, 2, 3) for d in (float, wp.vec2, wp.vec4)}
WIDTH = {float: 1, wp.vec2: 2, wp.vec4: 4}


def _run(tex, uv: np.ndarray, dtype, backend: str, device: str, lod: float = -1.0):
    ndim = tex.ndim
    coords = wp.array(uv[:, 0] if ndim == 1 else uv, dtype=COORDS[ndim], device=device)
    out = wp.zeros(len(uv), dtype=dtype, device=device)
    wp.launch(SAMPLERS[ndim, dtype], len(uv), inputs=[tex, coords, lod, out], backend=backend,
              device=device)  # fmt: skip
    return out.numpy().reshape(len(uv), WIDTH[dtype])


def _points(rng, n: int, ndim: int, normalized: bool, shape) -> np.ndarray:
    """Points inside, around and far outside the texture."""
    uv = rng.uniform(-1.3, 2.4, (n, ndim)).astype(np.float32)
    if not normalized:
        uv *= np.array(shape[::-1][:ndim], np.float32)
    return uv


def _check(tex, data, uv, dtype, backend, device, modes, filter_mode, normalized, **kw):
    texels = data.reshape((1,) * (3 - tex.ndim) + data.shape[: tex.ndim] + (-1,))
    levels = [decode(x) for x in box_levels(texels, tex.ndim, tex.num_mip_levels)]
    want = sample(levels, uv, modes, filter_mode, normalized, channels=WIDTH[dtype], **kw)
    got = _run(tex, uv, dtype, backend, device, kw.get("lod", -1.0))
    np.testing.assert_allclose(got, want, rtol=2e-5, atol=2e-5)
    return got


@pytest.mark.parametrize("backend,device", BACKENDS)
@pytest.mark.parametrize("mode", [WRAP, CLAMP, MIRROR, BORDER])
@pytest.mark.parametrize("filter_mode", [CLOSEST, LINEAR])
@pytest.mark.parametrize("normalized", [True, False])
def test_2d_float_modes_match_the_reference(backend, device, mode, filter_mode, normalized):
    rng = np.random.default_rng(mode * 4 + filter_mode * 2 + normalized)
    data = rng.random((5, 7), dtype=np.float32)
    tex = wp.Texture2D(data, filter_mode=filter_mode, address_mode=mode,
                       normalized_coords=normalized, device=device)  # fmt: skip
    uv = _points(rng, 60, 2, normalized, data.shape)
    got = _check(tex, data, uv, float, backend, device, (mode, mode), filter_mode, normalized)
    if mode == BORDER:  # some points fall outside, where the border reads zero
        assert (got == 0).any() and (got != 0).any()


@pytest.mark.parametrize("backend,device", BACKENDS)
@pytest.mark.parametrize("ndim", [1, 3])
@pytest.mark.parametrize("filter_mode", [CLOSEST, LINEAR])
def test_1d_and_3d_per_axis_modes_match_the_reference(backend, device, ndim, filter_mode):
    rng = np.random.default_rng(ndim + filter_mode)
    shape = (6,) if ndim == 1 else (3, 4, 5)
    data = rng.random(shape + (2,), dtype=np.float32)
    modes = (MIRROR,) if ndim == 1 else (WRAP, BORDER, MIRROR)
    for normalized in (True, False):
        tex = TEXTURES[ndim](data, filter_mode=filter_mode, address_mode=modes,
                             normalized_coords=normalized, device=device)  # fmt: skip
        assert tex.num_channels == 2
        uv = _points(rng, 40, ndim, normalized, shape)
        _check(tex, data, uv, wp.vec2, backend, device, modes, filter_mode, normalized)


FORMATS = [np.uint8, np.uint16, np.int8, np.int16, np.float16, np.float32, np.uint32, np.int32]


def _texels(rng, shape, fmt) -> np.ndarray:
    if np.issubdtype(fmt, np.integer):
        info = np.iinfo(fmt)
        return rng.integers(info.min, info.max, shape, endpoint=True).astype(fmt)
    return (rng.standard_normal(shape) * 3).astype(fmt)


@pytest.mark.parametrize("backend,device", BACKENDS)
@pytest.mark.parametrize("fmt", FORMATS, ids=lambda f: np.dtype(f).name)
def test_texel_formats_read_normalized_as_warp_documents(backend, device, fmt):
    rng = np.random.default_rng(3)
    data = _texels(rng, (4, 5, 4), fmt)
    data[0, 0] = np.iinfo(fmt).min if np.issubdtype(fmt, np.integer) else -1.5  # -128 -> -1
    integer32 = np.dtype(fmt).itemsize == 4 and np.issubdtype(fmt, np.integer)
    filters = [CLOSEST] if integer32 else [CLOSEST, LINEAR]
    for filter_mode in filters:
        tex = wp.Texture2D(data, filter_mode=filter_mode, address_mode=WRAP, device=device)
        assert tex.dtype is wp.dtype_from_numpy(np.dtype(fmt))
        uv = _points(rng, 40, 2, True, data.shape)
        uv[0] = (0.5 / 5, 0.5 / 4)  # texel (0, 0): the clamped minimum
        got = _check(tex, data, uv, wp.vec4, backend, device, (WRAP, WRAP), filter_mode, True)
        if fmt in (np.int8, np.int16) and filter_mode == CLOSEST:
            assert got[0, 0] == -1.0
        if fmt in (np.uint8, np.uint16):
            assert got.min() >= 0 and got.max() <= 1


@pytest.mark.parametrize("backend,device", BACKENDS)
@pytest.mark.parametrize("mip_filter", [CLOSEST, LINEAR])
def test_mip_levels_match_the_reference(backend, device, mip_filter):
    rng = np.random.default_rng(11)
    data = rng.random((8, 12, 1), dtype=np.float32)
    tex = wp.Texture2D(data, num_mip_levels=0, mip_filter_mode=mip_filter, address_mode=MIRROR,
                       device=device)  # fmt: skip
    assert tex.num_mip_levels == 4 and tex.is_mipmapped
    uv = _points(rng, 30, 2, True, data.shape)
    for lod in (-1.0, 0.0, 0.4, 1.5, 2.0, 2.75, 9.0):
        _check(tex, data[..., 0], uv, float, backend, device, (MIRROR, MIRROR), LINEAR, True,
               lod=lod, mip_filter_mode=mip_filter)  # fmt: skip


@pytest.mark.parametrize("backend,device", BACKENDS)
def test_mip_levels_of_integer_texels_round_like_warp(backend, device):
    data = np.array([[0, 255, 1, 2], [7, 8, 9, 100]], np.uint8)
    tex = wp.Texture2D(data, num_mip_levels=2, filter_mode=CLOSEST, device=device)
    got = _run(tex, np.array([[0.25, 0.5], [0.75, 0.5]], np.float32), float, backend, device, 1.0)
    # level 1 is ((0+255+7+8)/4, (1+2+9+100)/4) = (67.5, 28), rounded half to even
    np.testing.assert_allclose(got[:, 0], np.array([68, 28]) / 255, rtol=1e-6)


@pytest.mark.parametrize("backend,device", BACKENDS)
def test_one_channel_read_as_vec4_gives_zero_channels(backend, device):
    tex = wp.Texture1D(np.array([1.0, 3.0], np.float32), filter_mode=LINEAR,
                       normalized_coords=False, device=device)  # fmt: skip
    got = _run(tex, np.array([[1.0], [1.5]], np.float32), wp.vec4, backend, device)
    np.testing.assert_array_equal(got, [[2.0, 0, 0, 0], [3.0, 0, 0, 0]])


@pytest.mark.parametrize("backend,device", BACKENDS)
def test_warps_documented_example(backend, device):
    """The example of Warp's ``texture_sample`` docstring prints ``5.0 1.0 1.0``."""

    t1 = wp.Texture1D(np.array([0.0, 10.0, 20.0, 30.0], np.float32), filter_mode=LINEAR,
                      normalized_coords=False, device=device)  # fmt: skip
    t2 = wp.Texture2D(np.array([[0.0, 1.0], [2.0, 3.0]], np.float32), filter_mode=CLOSEST,
                      normalized_coords=False, device=device)  # fmt: skip
    t3 = wp.Texture3D(np.arange(8, dtype=np.float32).reshape(2, 2, 2), filter_mode=CLOSEST,
                      normalized_coords=False, device=device)  # fmt: skip
    out = wp.zeros(6, dtype=float, device=device)
    wp.launch(documented, 1, inputs=[t1, t2, t3, out], backend=backend, device=device)
    np.testing.assert_array_equal(out.numpy(), [5.0, 1.0, 1.0, 4.0, 2.0 * 2 + 2, 1.0])


@wp.kernel
def documented(t1: wp.Texture1D, t2: wp.Texture2D, t3: wp.Texture3D, out: wp.array(dtype=float)):
    out[0] = wp.texture_sample(t1, 1.0, dtype=float)
    out[1] = wp.texture_sample(t2, wp.vec2(1.5, 0.5), dtype=float)
    out[2] = wp.texture_sample(t3, wp.vec3(1.5, 0.5, 0.5), dtype=float)
    out[3] = float(t1.width)
    out[4] = float(t2.width * t2.height + t3.depth)
    out[5] = wp.texture_sample(t2, 1.5, 0.5, float)  # u, v and a positional dtype


@wp.kernel
def sample_uv(tex: wp.Texture2D, uv: wp.array(dtype=wp.vec2), lod: wp.array(dtype=float),
              out: wp.array(dtype=float)):  # fmt: skip
    i = wp.tid()
    out[i] = wp.texture_sample(tex, uv[i], dtype=float, lod=lod[i])


@pytest.mark.parametrize("backend,device", BACKENDS)
def test_gradients_by_uv_and_lod_match_central_differences(backend, device):
    rng = np.random.default_rng(5)
    data = rng.random((8, 8), dtype=np.float32)
    tex = wp.Texture2D(data, num_mip_levels=3, address_mode=WRAP, device=device)
    # away from texel centers, cell edges and integer lods, where the sample is smooth
    uv = np.array([[0.23, 0.61], [0.77, 0.12], [1.31, -0.4]], np.float32)
    lod = np.array([-1.0, 0.3, 1.6], np.float32)
    uv_a = wp.array(uv, dtype=wp.vec2, device=device, requires_grad=True)
    lod_a = wp.array(lod, dtype=float, device=device, requires_grad=True)
    out = wp.zeros(3, dtype=float, device=device, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(sample_uv, 3, inputs=[tex, uv_a, lod_a, out], backend=backend, device=device)
    tape.backward(grads={out: wp.ones(3, dtype=float, device=device)})
    g_uv, g_lod = uv_a.grad.numpy(), lod_a.grad.numpy()

    def f(uv_, lod_):
        res = wp.zeros(3, dtype=float, device=device)
        wp.launch(sample_uv, 3, inputs=[tex, wp.array(uv_, dtype=wp.vec2, device=device),
                  wp.array(lod_, dtype=float, device=device), res], backend=backend,
                  device=device)  # fmt: skip
        return res.numpy().astype(np.float64)

    h = 1e-3
    for a in range(2):
        e = np.zeros_like(uv)
        e[:, a] = h
        np.testing.assert_allclose(g_uv[:, a], (f(uv + e, lod) - f(uv - e, lod)) / (2 * h),
                                   rtol=2e-2, atol=2e-2)  # fmt: skip
    fd = (f(uv, lod + h) - f(uv, lod - h)) / (2 * h)
    np.testing.assert_allclose(g_lod[1:], fd[1:], rtol=2e-2, atol=2e-2)
    assert g_lod[0] == 0 and np.abs(g_uv).max() > 1  # lod < 0: level 0, no lod gradient


@cuda
@pytest.mark.parametrize("ndim", [1, 2, 3])
def test_cuda_samples_equal_the_cpu_backends_bit_for_bit(ndim):
    """NVRTC builds without FMA contraction: the same float32 arithmetic as the cpu."""
    rng = np.random.default_rng(21)
    shape = {1: (33,), 2: (9, 14), 3: (5, 6, 7)}[ndim] + (4,)
    data = (rng.standard_normal(shape) * 4).astype(np.float32)
    for mode in (WRAP, CLAMP, MIRROR, BORDER):
        for filter_mode, normalized in ((LINEAR, True), (LINEAR, False), (CLOSEST, True)):
            uv = _points(rng, 200, ndim, normalized, shape[:-1])
            got = []
            for device in ("cpu", "cuda:0"):
                tex = TEXTURES[ndim](data, filter_mode=filter_mode, address_mode=mode,
                                     normalized_coords=normalized, num_mip_levels=0,
                                     device=device)  # fmt: skip
                got.append(_run(tex, uv, wp.vec4, device.split(":")[0], device, lod=0.6))
            np.testing.assert_array_equal(got[1], got[0])
