"""Bad textures and bad ``texture_sample`` calls: clear kdsl errors (with the kernel's file,
line and source line for kernel code), never a NumPy traceback or a wrong sample."""

import textwrap
import types

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslLaunchError, KdslTypeError
from kdsl.texture.formats import TextureError


def _kernel(tmp_path, params: str, body: str):
    """A kernel compiled from a file, so that errors can name it."""
    src = textwrap.dedent(f"""\
        import kdsl as wp

        @wp.kernel
        def bad({params}):
            {body}
        """)  # fmt: skip
    path = tmp_path / "bad_texture.py"
    path.write_text(src)
    mod = types.ModuleType("bad_texture")
    exec(compile(src, str(path), "exec"), mod.__dict__)
    return mod.bad, path


TEX2 = "t: wp.Texture2D, out: wp.array(dtype=float)"


@pytest.mark.parametrize("params,body,match", [
    (TEX2, "out[0] = wp.texture_sample(t, wp.vec3(0.5), dtype=float)",
     r"a 2-d texture is sampled at uv \(a vec2f\) or u, v \(two floats\), got \(vec<3, f32>\)"),
    (TEX2, "out[0] = wp.texture_sample(t, 0.5, dtype=float)", r"2-d texture .*got \(the literal"),
    (TEX2, "out[0] = wp.texture_sample(t, wp.vec2d(0.5, 0.5), dtype=float)",
     r"got \(vec<2, f64>\)"),
    (TEX2, "out[0] = wp.texture_sample(t, wp.vec2(0.5))",
     r"texture_sample\(\) needs the sample type: texture_sample\(tex, uv, dtype=float\)"),
    (TEX2, "out[0] = wp.texture_sample(t, wp.vec2(0.5), dtype=wp.vec3)",
     r"unsupported texture type vec<3, f32>; dtype is float, vec2f or vec4f"),
    (TEX2, "out[0] = wp.texture_sample(t, wp.vec2(0.5), dtype=wp.float64)",
     r"unsupported texture type f64"),
    (TEX2, "out[0] = wp.texture_sample(t, wp.vec2(0.5), dtype=float, lod=wp.vec2())",
     r"lod must be a float, got a value of type vec<2, f32>"),
    (TEX2, "out[0] = wp.texture_sample(out, wp.vec2(0.5), dtype=float)",
     r"the first argument must be a Texture1D, Texture2D or Texture3D, got array<f32, 1>"),
    ("t: wp.Texture3D, out: wp.array(dtype=float)",
     "out[0] = wp.texture_sample(t, wp.vec2(0.5), dtype=float)",
     r"a 3-d texture is sampled at uvw \(a vec3f\) or u, v, w \(three floats\)"),
    ("t: wp.Texture1D, out: wp.array(dtype=float)",
     "out[0] = wp.texture_sample(t, wp.vec2(0.5), dtype=float)", r"1-d texture .* u \(a float\)"),
    (TEX2, "out[0] = wp.texture_sample(t, wp.vec2(0.5), float, 1.0, 2.0)",
     r"too many arguments"),
])  # fmt: skip
def test_bad_calls_are_errors_at_the_call(tmp_path, params, body, match):
    kernel, path = _kernel(tmp_path, params, body)
    tex = wp.Texture2D(np.zeros((2, 2), np.float32), device="cpu")
    with pytest.raises(KdslTypeError, match=match) as err:
        wp.launch(kernel, 1, inputs=[tex, wp.zeros(1)], backend="interp")
    text = str(err.value)
    assert str(path) in text and "line 5" in text and "texture_sample" in text


def test_a_texture2d_where_a_texture3d_is_annotated_is_a_launch_error(tmp_path):
    kernel, _ = _kernel(tmp_path, "t: wp.Texture3D, out: wp.array(dtype=float)",
                        "out[0] = wp.texture_sample(t, wp.vec3(0.5), dtype=float)")  # fmt: skip
    tex = wp.Texture2D(np.zeros((2, 2), np.float32), device="cpu")
    with pytest.raises(KdslLaunchError, match=r"argument 0 't': expected struct<Texture3D>, got"):
        wp.launch(kernel, 1, inputs=[tex, wp.zeros(1)], backend="interp")
    with pytest.raises(KdslLaunchError, match=r"struct<Texture3D>, got NumPy float32 array"):
        wp.launch(kernel, 1, inputs=[np.zeros((2, 2, 2), np.float32), wp.zeros(1)],
                  backend="interp")  # fmt: skip


@pytest.mark.parametrize("make,match", [
    (lambda: wp.Texture2D(np.zeros((2, 2), np.float64)), r"unsupported texture dtype float64"),
    (lambda: wp.Texture2D(np.zeros(4, np.float32)), r"2-d texture data must be an array with 2"),
    (lambda: wp.Texture1D(np.zeros((2, 2, 2), np.float32)), r"got shape \(2, 2, 2\)"),
    (lambda: wp.Texture2D(np.zeros((2, 2, 3), np.float32)), r"num_channels must be 1, 2 or 4"),
    (lambda: wp.Texture3D(wp.zeros((2, 2), dtype=wp.vec4)),
     r"3-d texture data must be an array of vectors with 3 dims"),
    (lambda: wp.Texture2D(np.zeros((2, 2), np.int32), filter_mode=1),
     r"32-bit integer textures require filter_mode=TextureFilterMode.CLOSEST"),
    (lambda: wp.Texture2D(np.zeros((4, 4), np.uint32), num_mip_levels=2, mip_filter_mode=1),
     r"mipmapped textures require mip_filter_mode"),
    (lambda: wp.Texture2D(np.zeros((4, 4), np.float32), num_mip_levels=4),
     r"num_mip_levels \(4\) exceeds the maximum for base dimensions \(4, 4\) \(3\)"),
    (lambda: wp.Texture2D(width=4, height=4, num_channels=1, num_mip_levels=2),
     r"need data at construction"),
    (lambda: wp.Texture2D(np.zeros((2, 2), np.float32), address_mode=7),
     r"invalid texture address mode for axis 0: 7"),
    (lambda: wp.Texture2D(np.zeros((2, 2), np.float32), filter_mode="linear"),
     r"invalid texture filter mode: 'linear'"),
    (lambda: wp.Texture2D(np.zeros((2, 3), np.float32), width=2), r"width \(2\) does not match"),
    (lambda: wp.Texture2D(np.zeros((2, 2), np.float32), dtype=wp.uint8), r"dtype .* not match"),
    (lambda: wp.Texture2D(width=0, height=2), r"width must be a positive integer, got 0"),
    (lambda: wp.Texture2D([[1.0]]), r"must be a NumPy array or a kdsl.array, not list"),
    (lambda: wp.Texture2D(np.zeros((2, 2), np.float32), surface_access=True),
     r"surface_access .* not supported"),
    (lambda: wp.Texture(np.zeros((2, 2), np.float32)), r"kdsl.Texture1D, Texture2D or"),
])  # fmt: skip
def test_bad_textures_are_value_errors(make, match):
    with pytest.raises(TextureError, match=match) as err:
        make()
    assert isinstance(err.value, ValueError)


def test_copies_check_shapes_and_round_trip():
    data = np.arange(12, dtype=np.uint16).reshape(3, 4)
    tex = wp.Texture2D(data, device="cpu")
    out = np.zeros((3, 4), np.uint16)
    tex.copy_to(out)
    np.testing.assert_array_equal(out, data)
    tex.copy_from(data[::-1].copy())
    dst = wp.zeros((3, 4), dtype=wp.uint16)
    tex.copy_to(dst)
    np.testing.assert_array_equal(dst.numpy(), data[::-1])
    other = wp.Texture2D(width=4, height=3, num_channels=1, dtype=wp.uint16)
    other.copy_from(tex)
    other.copy_to(out)
    np.testing.assert_array_equal(out, data[::-1])
    with pytest.raises(TextureError, match=r"incompatible source: texture shape \(3, 4\)"):
        tex.copy_from(np.zeros((4, 3), np.uint16))
    with pytest.raises(TextureError, match=r"incompatible destination"):
        tex.copy_to(np.zeros((3, 4), np.float32))
    mipped = wp.Texture2D(np.zeros((4, 4), np.float32), num_mip_levels=0)
    with pytest.raises(TextureError, match=r"not supported for mipmapped textures"):
        mipped.copy_to(np.zeros((4, 4), np.float32))
    with pytest.raises(TextureError, match=r"no CUDA array"):
        _ = tex.cuda_array
