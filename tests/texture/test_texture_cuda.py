"""The texture samplers on the cuda backend without a GPU: the kernels of
``test_texture_sampling`` lower to CUDA C (always) and NVRTC compiles it (sm_90, where
CuPy's NVRTC is installed). Running them on a GPU is the ``cuda`` rows of the sampling
tests."""

import pytest
from test_texture_sampling import SAMPLERS, documented, sample_uv

import kdsl as wp
from kdsl.backends.cuda.lower import generate
from kdsl.passes import DEFAULT_PIPELINE, run_pipeline

#: The three texture records, one and four channels, a lod from an array.
KERNELS = [documented, SAMPLERS[3, wp.vec4], sample_uv]


def _cuda_c(kernel) -> str:
    module = kernel.build_module()
    run_pipeline(module, DEFAULT_PIPELINE)
    return generate(module, [kernel.key]).text


def test_texture_kernels_lower_to_cuda_c():
    text = _cuda_c(documented)  # all three texture records
    for n in (1, 2, 3):
        assert f"struct k_Texture{n}D" in text
    assert "__global__" in text


def test_texture_kernels_compile_through_nvrtc():
    pytest.importorskip("cupy_backends.cuda.libs.nvrtc")
    from kdsl.backends.cuda import BACKEND
    from kdsl.compiler import compile_kernel

    for kernel in KERNELS:
        compiled = compile_kernel(BACKEND, kernel.build_module(), kernel.key, {"arch": "sm_90"})
        assert compiled.payload.cubin("sm_90")[:4] == b"\x7fELF", kernel.key
