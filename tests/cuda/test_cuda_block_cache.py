"""Loops the ``block-cache`` pass marked, lowered through shared memory (``cuda/tiling``).

Without a GPU: the generated CUDA C's shape, and NVRTC compiles it (sm_90). With a
GPU (skipped otherwise): the tiled kernels give the cpu backend's results bit for
bit in IEEE builds (kdsl's IEEE CUDA builds match the cpu backend), and the plain
loop's results in fast-math builds, for extents around the tile length, launches
smaller than the arrays, and n-d launches.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

pytest.importorskip("cupy_backends.cuda.libs.nvrtc")

import kdsl as wp
from kdsl.backends.cuda import BACKEND, nvrtc
from kdsl.backends.cuda.lower import without_fast_entries
from kdsl.compiler import lower
from kdsl.passes import DEFAULT_PIPELINE
from kdsl.testing.cases import all_cases
from kdsl.testing.cases.programs import make_programs

ARCH = "sm_90"
needs_gpu = pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA GPU")


def _nbody(**options) -> wp.Kernel:
    """A fresh n-body kernel object with ``options`` (compiled on its first launch)."""
    return wp.kernel(**options)(make_programs()["nbody"].func)


nbody = _nbody()
nbody_fast = _nbody(fast_math=True)


@wp.kernel
def smooth_in_place(x: wp.array(dtype=float), n: int):
    """Reads x[j] for all j and writes x[i]: must not be tiled."""
    i = wp.tid()
    s = 0.0
    for j in range(n):
        s = s + x[j]
    x[i] = s


@wp.kernel
def two_loops_2d(a: wp.array(dtype=float), b: wp.array(dtype=wp.float64),
                 out: wp.array2d(dtype=wp.float64), lo: int):  # fmt: skip
    """Two tiled loops in one kernel (one with parameter bounds), on a 2-d launch."""
    i, k = wp.tid()
    s = 0.0
    for j in range(a.shape[0]):
        s = s + a[j] * float(i + 1) - a[j] * a[j]
    t = wp.float64(0.0)
    for j in range(lo, b.shape[0] - 1):
        t = t + b[j] * wp.float64(k + 1)
    out[i, k] = wp.float64(s) + t


@wp.kernel
def mat_budget(m: wp.array(dtype=wp.mat44), w: wp.array(dtype=float), out: wp.array(dtype=float)):
    """A tile of 256 mat44 fills the 16 KiB budget: w[j] stays a global load."""
    i = wp.tid()
    s = 0.0
    for j in range(m.shape[0]):
        s = s + m[j][0, 0] * w[j]
    out[i] = s


def _cuda_c(kernel, **options) -> str:
    """The general entries' CUDA C (fast entries, ``cuda/variants.py``, left out)."""
    return without_fast_entries(lower(BACKEND, kernel, "cuda-c", options))


# -- without a GPU -----------------------------------------------------------------------
def test_nbody_loop_reads_shared_tiles():
    src = _cuda_c(nbody)
    assert re.search(r"__shared__ kd_vec3_f32 v\d+\[256\];", src)
    assert re.search(r"__shared__ float v\d+\[256\];", src)
    assert src.count("__syncthreads();") == 2
    assert "min(blockDim.x, kd_g.n - blockIdx.x * blockDim.x)" in src
    # the body reads the tiles, so the only global loads of pos and mass are
    # p = pos[i] and the cooperative loads
    assert len(re.findall(r"kd_at1\(v0,", src)) == 2
    assert len(re.findall(r"kd_at1\(v1,", src)) == 1
    assert re.search(r"= v\d+\[v\d+\]; kd_vec3_f32 v\d+ = kd_sub\(", src)


def test_array_written_by_the_kernel_is_not_tiled():
    src = _cuda_c(smooth_in_place)
    assert "__shared__" not in src and "__syncthreads" not in src


def test_debug_build_keeps_the_plain_loop():
    src = _cuda_c(nbody, debug=True)
    assert "kd_err" in src
    assert "__shared__" not in src and "__syncthreads" not in src


def test_budget_caches_only_what_fits():
    src = _cuda_c(mat_budget)
    assert len(re.findall(r"__shared__ kd_mat4x4_f32 v\d+\[256\];", src)) == 1
    assert "__shared__ float" not in src


def test_plain_pipeline_gives_the_plain_loop(monkeypatch):
    monkeypatch.setattr(BACKEND, "pipeline", DEFAULT_PIPELINE)
    assert "__shared__" not in _cuda_c(_nbody())


@pytest.mark.parametrize("fast", [False, True])
@pytest.mark.parametrize("kernel", [nbody, two_loops_2d, mat_budget], ids=["nbody", "2d", "mat"])
def test_tiled_kernels_compile(kernel, fast):
    src = _cuda_c(kernel)
    assert "__syncthreads" in src
    ptx = nvrtc.compile_source(src, ARCH, fast).ptx
    assert "bar.sync" in ptx and ".shared" in ptx


def test_tiled_conformance_kernels_compile():
    """Every conformance kernel the cuda pipeline tiles compiles (some must exist)."""
    units = []
    for case in all_cases():
        src = _cuda_c(case.kernel)
        if "__syncthreads" in src:
            units.append(src)
    assert len(units) >= 2
    for src in units:
        nvrtc.compile_source(src, ARCH)


def test_ieee_sqrt_and_division_stay_correctly_rounded():
    """The tiled n-body's PTX keeps IEEE square root and reciprocal, no approximations."""
    ptx = nvrtc.compile_source(_cuda_c(nbody), ARCH, False).ptx
    assert "sqrt.rn.f32" in ptx and "rcp.rn.f32" in ptx
    assert "approx" not in ptx and "fma" not in ptx


# -- on a GPU ------------------------------------------------------------------------------
DEVICE = "cuda:0"


def _nbody_on(kernel, device, pos, mass, dim):
    acc = wp.zeros(len(pos), dtype=wp.vec3, device=device)
    args = [wp.array(pos, dtype=wp.vec3, device=device), wp.array(mass, device=device), acc, 0.01]
    wp.launch(kernel, dim=dim, inputs=args, device=device)
    return acc.numpy()


def _inputs(n: int):
    rng = np.random.default_rng(n)
    return rng.normal(size=(n, 3)).astype(np.float32), rng.uniform(0.5, 1.5, n).astype(np.float32)


_EXTENTS = [(1, 1), (5, 5), (255, 255), (256, 256), (257, 257), (1000, 1000), (600, 5),
            (600, 300), (100, 100)]  # fmt: skip


def _plain_kernel(monkeypatch, **options):
    """The n-body kernel compiled without block-cache (a fresh kernel object)."""
    monkeypatch.setattr(BACKEND, "pipeline", DEFAULT_PIPELINE)
    kernel = _nbody(**options)
    assert "__shared__" not in _cuda_c(kernel)
    return kernel


@needs_gpu
@pytest.mark.parametrize("n, dim", _EXTENTS)
def test_tiled_nbody_matches_the_plain_loop_bit_for_bit(n, dim, monkeypatch):
    pos, mass = _inputs(n)
    assert "__shared__" in _cuda_c(nbody)
    tiled = _nbody_on(nbody, DEVICE, pos, mass, dim)
    plain = _nbody_on(_plain_kernel(monkeypatch), DEVICE, pos, mass, dim)
    np.testing.assert_array_equal(tiled.view(np.uint32), plain.view(np.uint32))


@needs_gpu
@pytest.mark.parametrize("n, dim", _EXTENTS)
def test_tiled_nbody_matches_cpu_bit_for_bit(n, dim):
    pos, mass = _inputs(n)
    got = _nbody_on(nbody, DEVICE, pos, mass, dim)
    want = _nbody_on(nbody, "cpu", pos, mass, dim)
    np.testing.assert_array_equal(got.view(np.uint32), want.view(np.uint32))


@needs_gpu
@pytest.mark.parametrize("n, dim", [(257, 257), (1000, 3), (4096, 4096)])
def test_tiled_fast_math_matches_the_plain_loop(n, dim, monkeypatch):
    pos, mass = _inputs(n)
    tiled = _nbody_on(nbody_fast, DEVICE, pos, mass, dim)
    plain = _nbody_on(_plain_kernel(monkeypatch, fast_math=True), DEVICE, pos, mass, dim)
    np.testing.assert_allclose(tiled, plain, rtol=1e-6, atol=1e-6)


@needs_gpu
@pytest.mark.parametrize("shape", [(3, 5), (17, 31), (300, 2)])
def test_two_tiled_loops_on_a_2d_launch_match_cpu(shape):
    rng = np.random.default_rng(1)
    a = rng.normal(size=700).astype(np.float32)
    b = rng.normal(size=260)

    def run(device):
        out = wp.zeros(shape, dtype=wp.float64, device=device)
        args = [wp.array(a, device=device), wp.array(b, dtype=wp.float64, device=device), out, 3]
        wp.launch(two_loops_2d, dim=shape, inputs=args, device=device)
        return out.numpy()

    np.testing.assert_array_equal(run(DEVICE), run("cpu"))


@needs_gpu
def test_untiled_in_place_kernel_matches_cpu():
    x = np.arange(50, dtype=np.float32)

    def run(device):
        arr = wp.array(x, device=device)
        wp.launch(smooth_in_place, dim=1, inputs=[arr, 50], device=device)
        return arr.numpy()

    np.testing.assert_array_equal(run(DEVICE), run("cpu"))
