"""The cpu backend's inline float32 ``sin``/``cos`` (``kdsl/backends/cpu/trig.py``).

What the IR holds (one range reduction for a ``sin`` and a ``cos`` of one value, no
libm call on the fast path, float64 untouched), and that vectors, float16 and
``fast_math`` kernels get the same accurate results. Accuracy over ranges and special
values: ``tests/conformance/test_sincos_accuracy.py``.
"""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.backends.cpu import trig
from kdsl.compiler import lower
from kdsl.testing.conformance import ulp_distance


def _ir(kernel, stage: str = "llvm-ir", options: dict | None = None) -> str:
    from kdsl.backends.cpu import BACKEND

    return lower(BACKEND, kernel.build_module(), stage, options)


def _wave(
    x: wp.array(dtype=float),
    k: wp.array(dtype=float),
    out: wp.array(dtype=wp.vec2),
):
    i = wp.tid()
    acc = wp.vec2(0.0, 0.0)
    for w in range(k.shape[0]):
        theta = k[w] * x[i]
        acc = acc + wp.vec2(wp.sin(theta), wp.cos(theta))
    out[i] = acc


wave = wp.kernel(_wave)
wave_fast = wp.kernel(fast_math=True)(_wave)


@wp.kernel
def sin_only(x: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = wp.sin(x[i])


def _sin_cos(x: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = wp.sin(x[i]) * wp.cos(x[i])


sin_cos = wp.kernel(_sin_cos)
sin_cos_fast = wp.kernel(fast_math=True)(_sin_cos)


@wp.kernel
def sincos_f32(x: wp.array(dtype=float), s: wp.array(dtype=float), c: wp.array(dtype=float)):
    i = wp.tid()
    s[i] = wp.sin(x[i])
    c[i] = wp.cos(x[i])


def _sincos_in_loop(x: wp.array(dtype=float), reps: int, s: wp.array(dtype=float),
                    c: wp.array(dtype=float)):  # fmt: skip
    # A float sum over a loop (as in the ocean): the loop over j does not vectorize; the
    # threads do in lane blocks (``lane_blocks``), not in a debug build, whose code is
    # scalar. -0.0 is the sum's identity and x - 0.0 is x, so reps = 1 gives sin x, cos x.
    i = wp.tid()
    acc_s = wp.float32(-0.0)
    acc_c = wp.float32(-0.0)
    for j in range(reps):
        a = x[i] - float(j)
        acc_s = acc_s + wp.sin(a)
        acc_c = acc_c + wp.cos(a)
    s[i] = acc_s
    c[i] = acc_c


sincos_in_loop = wp.kernel(_sincos_in_loop)
sincos_in_loop_scalar = wp.kernel(debug=True)(_sincos_in_loop)


@wp.kernel
def sin_f64(x: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.float64)):
    i = wp.tid()
    out[i] = wp.sin(x[i]) + wp.cos(x[i])


@wp.kernel
def sincos_vec3(x: wp.array(dtype=wp.vec3), s: wp.array(dtype=wp.vec3), c: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    s[i] = wp.sin(x[i])
    c[i] = wp.cos(x[i])


@wp.kernel
def sincos_f16(x: wp.array(dtype=wp.float16), s: wp.array(dtype=wp.float16),
               c: wp.array(dtype=wp.float16)):  # fmt: skip
    i = wp.tid()
    s[i] = wp.sin(x[i])
    c[i] = wp.cos(x[i])


def _llvm_hex(v: float) -> str:
    return "0x" + np.float64(v).view(np.uint64).tobytes()[::-1].hex().upper()


def test_sin_and_cos_of_one_value_share_one_reduction(cpu_backend):
    text = _ir(wave)
    # Per copy of the loop body (lane blocks and the threads after them, ``lane_blocks``):
    # one multiply by 2/pi (the reduction), one polynomial of each kind.
    copies = text.count(_llvm_hex(trig.TWO_OVER_PI))
    assert copies >= 1
    assert text.count(_llvm_hex(trig.SIN_COEFFS[0])) == copies
    assert text.count(_llvm_hex(trig.COS_COEFFS[0])) == copies
    for libm in ("@sinf", "@cosf", "@sincosf", "llvm.sin.", "llvm.cos."):
        assert libm not in text, libm


def _host_has(feature: str) -> bool:
    import llvmlite.binding as llvm

    return bool(llvm.get_host_cpu_features().get(feature, False))


@pytest.mark.skipif(not _host_has("avx2"), reason="the vectorizer's choice depends on the host")
@pytest.mark.parametrize("kernel", [sin_only, sincos_f32], ids=["sin", "sincos"])
def test_elementwise_loop_vectorizes(cpu_backend, kernel):
    text = _ir(kernel)
    body = text.split("vector.body:")[1].split("\n\n")[0]
    assert "x double> @llvm.fmuladd" in body  # the reduction and polynomials, on lanes
    for libm in ("@sinf", "@cosf", "llvm.sin."):
        assert libm not in text, libm


def test_float64_keeps_libm(cpu_backend):
    text = _ir(sin_f64)
    assert "llvm.sin.f64" in text or "@sin(" in text or "@sincos(" in text
    assert trig.SYMBOL not in text


def _dense(n: int, seed: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.concatenate([rng.uniform(-50.0, 50.0, n), rng.uniform(-1e4, 1e4, n)]).astype(
        np.float32
    )


def test_fast_math_kernel_gives_the_same_bits(cpu_backend):
    x = _dense(1 << 16)
    outs = []
    for kern in (sin_cos, sin_cos_fast):
        out = wp.zeros(len(x), dtype=float, device="cpu")
        wp.launch(kern, len(x), [wp.array(x, dtype=float, device="cpu"), out], device="cpu",
                  backend="cpu")  # fmt: skip
        outs.append(out.numpy())
    np.testing.assert_array_equal(outs[1], outs[0])


def test_fast_math_loop_matches_float64(cpu_backend):
    x = _dense(4096)
    k = np.array([1.0, -0.5, 3.0], np.float32)
    outs = []
    for kern in (wave, wave_fast):
        xs = wp.array(x, dtype=float, device="cpu")
        ks = wp.array(k, dtype=float, device="cpu")
        out = wp.zeros(len(x), dtype=wp.vec2, device="cpu")
        wp.launch(kern, len(x), [xs, ks, out], device="cpu", backend="cpu")
        outs.append(out.numpy())
    # The kernel's own sum may be reassociated in the fast_math build.
    np.testing.assert_allclose(outs[1], outs[0], rtol=0, atol=4e-7 * len(k))
    theta = k[None, :].astype(np.float32) * x[:, None]
    want = np.stack([np.sin(theta.astype(np.float64)).sum(1),
                     np.cos(theta.astype(np.float64)).sum(1)], axis=1)  # fmt: skip
    np.testing.assert_allclose(outs[0], want, rtol=0, atol=1e-6)


def test_fast_math_helper_carries_no_flags(cpu_backend):
    text = _ir(wave_fast, "llvm-ir-unopt", {"fast_math": True})
    body = text.split(f'define internal {{float, float}} @"{trig.SYMBOL}"(')[1].split("\n}\n")[0]
    assert "double" in body
    for flag in ("reassoc", "fast", "contract", "afn"):
        assert f" {flag} " not in body, flag


# vec3 components: float32 within 0.51 ulp; float16 (computed in float32, 0.51 ulp of
# float32, then rounded): at most 0.5 + 2^-13 ulp of float16.
@pytest.mark.parametrize(
    "kernel, dtype, x, max_ulp",
    [
        (sincos_vec3, wp.vec3, _dense(513).reshape(-1, 3), 0.51),
        (sincos_f16, wp.float16, np.linspace(-60.0, 60.0, 3001).astype(np.float16), 0.501),
    ],
    ids=["vec3", "float16"],
)
def test_vectors_and_float16(cpu_backend, kernel, dtype, x, max_ulp):
    xs = wp.array(x, dtype=dtype, device="cpu")
    s = wp.zeros(len(x), dtype=dtype, device="cpu")
    c = wp.zeros(len(x), dtype=dtype, device="cpu")
    wp.launch(kernel, len(x), [xs, s, c], device="cpu", backend="cpu")
    d = x.astype(np.float64)
    assert ulp_distance(s.numpy(), np.sin(d)).max() <= max_ulp
    assert ulp_distance(c.numpy(), np.cos(d)).max() <= max_ulp


def test_scalar_path_matches_the_vectorized_one(cpu_backend):
    # The accuracy tests run an elementwise kernel, which LLVM vectorizes; a debug build
    # of this one keeps the scalar code (branch to the table reduction), its lane blocks
    # vectorize: all three must give the same bits.
    from kdsl.backends.cpu import jit
    from kdsl.backends.cpu.lower import lower_kernels

    state = lower_kernels(sincos_in_loop_scalar.build_module(), [sincos_in_loop_scalar.key],
                          debug=True)  # fmt: skip
    text = str(jit.optimize(jit.parse(str(state.llmod))))
    # One copy of the reduction, in no vectorized loop (reps <= 0 stores -0.0 vectorized).
    assert text.count(_llvm_hex(trig.TWO_OVER_PI)) == 1
    vector_loops = text.split("vector.body:")[1:]
    assert not any(_llvm_hex(trig.TWO_OVER_PI) in v.split("\n\n")[0] for v in vector_loops)
    big = np.array([1048576.0, -3e6, 1e10, -3.4028235e38, np.inf, -np.inf, np.nan], np.float32)
    tiny = np.array([0.0, -0.0, 1e-45, -1e-40], np.float32)
    x = np.concatenate([_dense(1 << 15), big, tiny, _dense(64, seed=4) * 1e4])
    xs = wp.array(x, dtype=float, device="cpu")
    got = []
    for kernel, extra in ((sincos_in_loop_scalar, [1]), (sincos_in_loop, [1]), (sincos_f32, [])):
        out = [wp.zeros(len(x), dtype=float, device="cpu") for _ in range(2)]
        wp.launch(kernel, len(x), [xs, *extra, *out], device="cpu", backend="cpu")
        got.append([a.numpy() for a in out])
    for scalar, *vectors in zip(*got):
        for vector in vectors:
            np.testing.assert_array_equal(scalar, vector)
            np.testing.assert_array_equal(np.signbit(scalar), np.signbit(vector))  # -0.0 too
    d = x.astype(np.float64)
    with np.errstate(invalid="ignore"):
        assert ulp_distance(got[0][0], np.sin(d)).max() <= 0.51
        assert ulp_distance(got[0][1], np.cos(d)).max() <= 0.51
