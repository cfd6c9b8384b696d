"""The cpu backend's ``fast_math`` kernel option: flags in the IR, close results."""

from __future__ import annotations

import re

import numpy as np

import kdsl as wp
from kdsl.backends.cpu.emitter import FAST_MATH_FLAGS
from kdsl.compiler import compile_kernel, lower


def _accelerations(
    pos: wp.array(dtype=wp.vec3),
    mass: wp.array(dtype=float),
    acc: wp.array(dtype=wp.vec3),
    eps2: float,
):
    i = wp.tid()
    p = pos[i]
    a = wp.vec3(0.0, 0.0, 0.0)
    for j in range(pos.shape[0]):
        d = pos[j] - p
        inv_r = 1.0 / wp.sqrt(wp.dot(d, d) + eps2)
        a = a + d * (mass[j] * inv_r * inv_r * inv_r)
    acc[i] = a


ieee = wp.kernel(_accelerations)
fast = wp.kernel(fast_math=True)(_accelerations)


@wp.kernel(fast_math=True)
def nan_check(x: wp.array(dtype=float), out: wp.array(dtype=wp.int32)):
    i = wp.tid()
    y = x[i] * 2.0
    if wp.isnan(y):
        out[i] = 1
    else:
        out[i] = 0


_FLOAT_OP = re.compile(r"= (fadd|fsub|fmul|fdiv) (.*?)(float|<)")


def _ir(kernel, stage: str, options: dict | None = None) -> str:
    from kdsl.backends.cpu import BACKEND

    return lower(BACKEND, kernel.build_module(), stage, options)


def _accs(cpu_backend, kernel, n: int = 300) -> np.ndarray:
    rng = np.random.default_rng(5)
    pos = wp.from_numpy(rng.normal(size=(n, 3)).astype(np.float32), dtype=wp.vec3, device="cpu")
    mass = wp.from_numpy(rng.uniform(0.5, 1.5, n).astype(np.float32), dtype=float, device="cpu")
    acc = wp.zeros(n, dtype=wp.vec3, device="cpu")
    wp.launch(kernel, dim=n, inputs=[pos, mass, acc, 0.01], device="cpu", backend=cpu_backend)
    return acc.numpy()


def test_fast_math_result_close_to_ieee(cpu_backend) -> None:
    want, got = _accs(cpu_backend, ieee), _accs(cpu_backend, fast)
    scale = np.max(np.abs(want))
    assert np.max(np.abs(got - want)) / scale < 2e-3
    assert np.all(np.isfinite(got))


def test_unoptimized_ir_has_the_flags() -> None:
    text = _ir(fast, "llvm-ir-unopt", {"fast_math": True})
    ops = _FLOAT_OP.findall(text)
    assert ops, "no float arithmetic found"
    for _, flags, _ in ops:
        assert set(flags.split()) == set(FAST_MATH_FLAGS), flags
    assert '"no-signed-zeros-fp-math"="true"' in text
    # One sqrt per copy of the j loop: in lane blocks (``lane_blocks``), and dense and
    # strided (``versioning``) for the threads after the last block.
    sqrts = [ln for ln in text.splitlines() if '@"llvm.sqrt' in ln and "call" in ln]
    assert len(sqrts) == 3
    for sqrt in sqrts:
        assert set(FAST_MATH_FLAGS) <= set(sqrt.split())


def test_default_build_has_no_fast_flags() -> None:
    for stage in ("llvm-ir-unopt", "llvm-ir"):
        text = _ir(fast, stage)  # no options: the IEEE build, whatever the kernel says
        assert not any(f in text for f in ("reassoc", "contract", "afn", "arcp", " nsz ", " fast "))
        assert "fp-math" not in text


def test_fast_math_never_assumes_no_nans(cpu_backend) -> None:
    # nnan/ninf are left out, so isnan still sees NaN in a fast-math kernel.
    x = wp.from_numpy(np.array([1.0, np.nan, np.inf, -2.0], np.float32), device="cpu")
    out = wp.zeros(4, dtype=wp.int32, device="cpu")
    wp.launch(nan_check, dim=4, inputs=[x, out], device="cpu", backend=cpu_backend)
    assert out.numpy().tolist() == [0, 1, 0, 0]
    assert "nnan" not in _ir(nan_check, "llvm-ir", {"fast_math": True})


def test_option_keys_the_cache(cpu_backend) -> None:
    from kdsl.backends.cpu import BACKEND

    a = compile_kernel(BACKEND, ieee.build_module(), ieee.key, {"fast_math": True})
    b = compile_kernel(BACKEND, ieee.build_module(), ieee.key, {})
    assert a.metadata["cache_key"] != b.metadata["cache_key"]


_WIDE_FLOAT_OP = re.compile(r"= (fmul|fadd|fsub) [a-z ]*<(4|8|16) x float>")


def test_fast_math_vec3_loop_is_vectorized() -> None:
    # vec3 values are scalarized and the dense copy of the j loop has constant strides,
    # so LLVM's loop vectorizer widens the n-body sum over j: wide float ops in a loop
    # whose header carries vector phis (the lanes of the split reduction).
    text = _ir(fast, "llvm-ir", {"fast_math": True})
    blocks = re.split(r"\n(?=[\w.]+:)", text)
    loops = [b for b in blocks if re.search(r"phi <(4|8|16) x float>", b)]
    assert loops, "no vectorized reduction loop"
    assert any(len(_WIDE_FLOAT_OP.findall(b)) >= 6 for b in loops)
    assert not re.search(r"<3 x float>", text)


def test_ieee_build_keeps_vec3_scalar_order() -> None:
    # Without reassoc the j sum stays sequential (results stay bit-identical), but no
    # LLVM vector of a vec3's three components is left either.
    text = _ir(ieee, "llvm-ir-unopt")
    assert "<3 x float>" not in text
    assert re.search(r"= fadd float", text)
