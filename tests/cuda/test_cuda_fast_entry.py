"""A kernel's fast entry (``kdsl/backends/cuda/variants.py``) and the launch-time
choice between it and the general entry (``cuda/geometry.py``).

Without a GPU: which kernels get a fast entry and what it does (n-d grid, 32-bit
offsets, ``__ldg`` on read-only parameters), that NVRTC builds it, and the launch-time
selection on simulated arguments (arrays of 2**31 bytes and more, overlapping read and
written arrays, grids taller than CUDA allows). With a GPU (skipped otherwise): the
fast entry gives the general entry's results bit for bit, and the cpu backend's, on
edge shapes (1xN, Nx1, odd sizes, 3-d), and the launch picks the entry it should.
"""

from __future__ import annotations

import re
from types import SimpleNamespace

import numpy as np
import pytest

pytest.importorskip("cupy_backends.cuda.libs.nvrtc")

import kdsl as wp
from kdsl.backends.cuda import BACKEND, nvrtc
from kdsl.backends.cuda import backend as cuda_backend
from kdsl.backends.cuda import geometry as G
from kdsl.backends.cuda.lower import BLOCK, fast_entry_name, without_fast_entries
from kdsl.backends.cuda.variants import FastPlan, fast_plan
from kdsl.compiler import lower
from kdsl.passes import run_pipeline
from kdsl.testing.cases.programs import make_programs

ARCH = "sm_90"
needs_gpu = pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA GPU")


@wp.kernel
def jacobi(u: wp.array2d(dtype=float), out: wp.array2d(dtype=float)):
    """A weighted 5-point smoothing step, edges copied (bounds tests inside)."""
    i, j = wp.tid()
    c = u[i, j]
    if i > 0 and j > 0 and i < out.shape[0] - 1 and j < out.shape[1] - 1:
        c = 0.5 * c + 0.125 * ((u[i - 1, j] + u[i + 1, j]) + (u[i, j - 1] + u[i, j + 1]))
    out[i, j] = c


@wp.kernel
def smooth3(u: wp.array3d(dtype=float), out: wp.array3d(dtype=float)):
    i, j, k = wp.tid()
    s = u[i, j, k]
    if k > 0:
        s = s + u[i, j, k - 1]
    if j + 1 < u.shape[1]:
        s = s * u[i, j + 1, k]
    out[i, j, k] = s + float(i * 1000 + j * 10 + k)


@wp.kernel
def gather_vec(x: wp.array(dtype=wp.vec3), idx: wp.array(dtype=int), flags: wp.array(dtype=wp.bool),
               out: wp.array(dtype=wp.vec3)):  # fmt: skip
    i = wp.tid()
    v = x[idx[i]]
    if flags[i]:
        v = v * 2.0
    out[i] = v


@wp.kernel
def in_place(a: wp.array(dtype=float)):
    i = wp.tid()
    a[i] = a[i] * 2.0 + 1.0


@wp.kernel
def copy_shift(src: wp.array(dtype=float), dst: wp.array(dtype=float)):
    i = wp.tid()
    dst[i] = src[i] + 1.0


@wp.struct
class Sink:
    a: wp.array(dtype=float)


@wp.kernel
def write_through_struct(x: wp.array(dtype=float), s: Sink):
    i = wp.tid()
    s.a[i] = x[i]


@wp.kernel
def uses_block_dim(a: wp.array2d(dtype=int)):
    i, j = wp.tid()
    a[i, j] = wp.block_dim()


@wp.kernel
def no_arrays(n: int):
    i = wp.tid()
    if i > n:
        wp.printf("%d\n", i)


@wp.kernel
def half_reads(h: wp.array(dtype=wp.float16), out: wp.array(dtype=wp.float16)):
    i = wp.tid()
    out[i] = h[i] + h[i]


def _plan(kernel, debug: bool = False) -> FastPlan | None:
    m = kernel.build_module()
    run_pipeline(m, BACKEND.pipeline)
    return fast_plan(m, kernel.key, debug)


def _entry(src: str, fast: bool) -> str:
    """The definition of the (fast or general) kernel entry in unit ``src``."""
    if not fast:
        text = without_fast_entries(src)
        return text[text.index('extern "C"') :]
    head = re.search(r'extern "C" __global__ [^\n]*_fast\(', src)
    assert head is not None
    body = src[head.start() :]
    return body[: body.index("\n}\n") + 3]


# -- which kernels get what -----------------------------------------------------------
def test_jacobi_fast_entry_uses_a_2d_grid_32bit_offsets_and_ldg():
    src = lower(BACKEND, jacobi, "cuda-c")
    fast, general = _entry(src, True), _entry(src, False)
    assert "blockIdx.y * blockDim.y + threadIdx.y" in fast and "%" not in fast
    assert "kd_g.dim[1] || kd_y >= kd_g.dim[0]" in fast
    assert len(re.findall(r"kd_ldg_f32\(kd_at2_32\(v0,", fast)) == 5
    assert "*(float *)kd_at2_32(v1," in fast and "kd_ldg_f32(kd_at2_32(v1" not in fast
    # the general entry is what it always was
    assert "kd_r % kd_g.dim[1]" in general and "kd_ldg" not in general and "_32(" not in general
    assert f"__launch_bounds__({BLOCK})" in fast and f"__launch_bounds__({BLOCK})" in general
    ptx = nvrtc.compile_source(src, ARCH).ptx
    body = ptx[ptx.index(f".entry {fast_entry_name(jacobi.key)}(") :]
    body = body[: body.index("\n}")]
    assert len(re.findall(r"ld\.global\.nc\.f32", body)) == 5
    assert not re.search(r"\b(div|rem)\.", body)
    # each address: a sum taken down to 32 bits and widened once (ptxas then uses
    # 32-bit multiply-adds)
    assert len(re.findall(r"cvt\.s64\.s32\s+%rd\d+, %rd\d+;", body)) >= 5


def test_jacobi_plan():
    assert _plan(jacobi) == FastPlan(2, ((0, 2, 4), (1, 2, 4)), (0,), (1,))


def test_3d_kernel_takes_z_for_its_first_index():
    plan = _plan(smooth3)
    assert plan is not None and plan.grid_nd == 3 and plan.read_only == (0,)
    src = lower(BACKEND, smooth3, "cuda-c")
    fast = _entry(src, True)
    assert "kd_z >= kd_g.dim[0]" in fast and "kd_x >= kd_g.dim[2]" in fast
    assert re.search(
        r"int v\d+ = \(int\)kd_z; int v\d+ = \(int\)kd_y; int v\d+ = \(int\)kd_x;", fast
    )
    nvrtc.compile_source(src, ARCH)


def test_vector_bool_and_int_loads_go_through_ldg():
    plan = _plan(gather_vec)
    assert plan is not None and plan.grid_nd == 0 and plan.read_only == (0, 1, 2)
    src = lower(BACKEND, gather_vec, "cuda-c")
    fast = _entry(src, True)
    for helper in ("kd_ldg_kd_vec3_f32", "kd_ldg_i32", "kd_ldg_b"):
        assert helper + "(" in fast
    assert "kd_i >= kd_g.n" in fast  # 1-d: the general entry's linear grid
    ptx = nvrtc.compile_source(src, ARCH).ptx
    assert "ld.global.nc.u8" in ptx or "ld.global.nc.s8" in ptx


def test_read_and_written_array_is_not_read_only():
    plan = _plan(in_place)
    assert plan is not None and plan.read_only == () and plan.written == (0,)
    assert "kd_ldg" not in lower(BACKEND, in_place, "cuda-c")


def test_a_write_the_parameters_do_not_cover_turns_ldg_off():
    plan = _plan(write_through_struct)
    assert plan is not None and plan.read_only == ()
    src = lower(BACKEND, write_through_struct, "cuda-c")
    assert "kd_ldg" not in src
    nvrtc.compile_source(src, ARCH)


def test_float16_loads_stay_plain():
    plan = _plan(half_reads)
    assert plan is not None and plan.read_only == ()
    nvrtc.compile_source(lower(BACKEND, half_reads, "cuda-c"), ARCH)


def test_block_dim_keeps_the_linear_grid():
    plan = _plan(uses_block_dim)
    assert plan is not None and plan.grid_nd == 0


def test_tiled_kernels_have_no_fast_entry():
    nbody = make_programs()["nbody"].func
    src = lower(BACKEND, wp.kernel(nbody), "cuda-c")
    assert "__syncthreads" in src and "_fast(" not in src


def test_no_fast_entry_without_arrays_or_in_debug_builds():
    assert _plan(no_arrays) is None
    assert "_fast(" not in lower(BACKEND, no_arrays, "cuda-c")
    assert _plan(jacobi, debug=True) is None
    assert "_fast(" not in lower(BACKEND, jacobi, "cuda-c", {"debug": True})


# -- the launch-time choice -------------------------------------------------------------
def _arr(ptr: int, shape: tuple, strides: tuple) -> SimpleNamespace:
    """What the launch reads of a CuPy array (no GPU memory behind it)."""
    return SimpleNamespace(data=SimpleNamespace(ptr=ptr), shape=shape, strides=strides)


def test_offsets_fit_up_to_int32():
    assert G.offsets_fit((2, 1), (G.INT32_MAX, 4))
    assert not G.offsets_fit((2, 1), (G.INT32_MAX + 1, 4))
    # 2**29 floats: the last element starts at 2**31 - 4
    assert G.offsets_fit((2**29,), (4,))
    assert not G.offsets_fit((2**29 + 1,), (4,))
    assert not G.offsets_fit((3, 2**28 + 1), (-(2**30), 4))  # negative strides count too
    assert G.offsets_fit((0, 2**40), (4, 4))  # empty
    assert G.offsets_fit((2**40,), (0,))  # broadcast: every index reaches offset 0


def test_byte_ranges_and_overlap():
    a = G.byte_range(_arr(1000, (10,), (4,)), 1, 4)
    assert a == (1000, 1040)
    assert G.byte_range(_arr(1000, (10,), (-4,)), 1, 4) == (964, 1004)
    assert G.byte_range(_arr(1000, (0, 3), (12, 4)), 2, 4) is None
    assert G.disjoint(a, (1040, 1100)) and G.disjoint((900, 1000), a)
    assert not G.disjoint(a, (1036, 1100)) and not G.disjoint(a, a)
    assert G.disjoint(a, None)


def _jacobi_args(rows: int, cols: int, same: bool = False) -> list:
    u = _arr(1 << 20, (rows, cols), (4 * cols, 4))
    out = u if same else _arr((1 << 20) + 4 * rows * cols, (rows, cols), (4 * cols, 4))
    return [u, out]


JACOBI_PLAN = FastPlan(2, ((0, 2, 4), (1, 2, 4)), (0,), (1,))


def test_fast_geometry_of_jacobi():
    got = G.fast_geometry(JACOBI_PLAN, _jacobi_args(4096, 4096), (4096, 4096), 4096 * 4096)
    assert got == ((16, 4096, 1), (256, 1, 1))


def test_an_array_needing_64bit_offsets_picks_the_general_entry():
    rows, cols = 2**16, 2**13 + 1  # 2**31 bytes and more
    args = _jacobi_args(rows, cols)
    assert G.fast_geometry(JACOBI_PLAN, args, (rows, cols), rows * cols) is None
    # the written array alone being too large is enough
    args[1] = _arr(1 << 44, (rows, cols), (4 * cols, 4))
    args[0] = _arr(1 << 20, (4, 4), (16, 4))
    assert G.fast_geometry(JACOBI_PLAN, args, (rows, cols), rows * cols) is None


def test_aliased_read_and_written_arrays_pick_the_general_entry():
    assert G.fast_geometry(JACOBI_PLAN, _jacobi_args(64, 64, same=True), (64, 64), 4096) is None
    # a view overlapping by one element
    u, out = _jacobi_args(8, 8)
    out = _arr(u.data.ptr + 4 * 63, (8, 8), (32, 4))
    assert G.fast_geometry(JACOBI_PLAN, [u, out], (8, 8), 64) is None
    # arrays that only touch are fine
    out = _arr(u.data.ptr + 4 * 64, (8, 8), (32, 4))
    assert G.fast_geometry(JACOBI_PLAN, [u, out], (8, 8), 64) is not None


def test_without_read_only_arrays_aliasing_is_not_checked():
    plan = FastPlan(0, ((0, 1, 4), (1, 1, 4)), (), (0, 1))
    a = _arr(4096, (100,), (4,))
    assert G.fast_geometry(plan, [a, a], (100,), 100) == G.linear_geometry(100)


@pytest.mark.parametrize(
    "dims",
    [(1, 1), (1, 5000), (5000, 1), (7, 13), (37, 291), (300, 257), (4096, 4096), (2, 3, 5),
     (1, 1, 700), (700, 1, 1), (3, 65, 129), (65535, 1), (65535 * 256, 1)],
)  # fmt: skip
def test_nd_geometry_covers_the_grid(dims):
    got = G.nd_geometry(dims)
    assert got is not None
    grid, block = got
    assert block[0] * block[1] * block[2] <= BLOCK
    for k, d in enumerate(reversed(dims)):
        assert grid[k] * block[k] >= d  # every index has a thread
        assert (grid[k] - 1) * block[k] < d  # and no block is wholly outside
    assert grid[1] <= G.GRID_YZ_MAX and grid[2] <= G.GRID_YZ_MAX
    assert all(g == 1 and b == 1 for g, b in zip(grid[len(dims) :], block[len(dims) :]))


def test_nd_geometry_falls_back_beyond_cuda_grid_limits():
    assert G.nd_geometry((65535 * 256 + 1, 1)) is None  # gridDim.y would be 65536
    assert G.nd_geometry((2**24, 2)) is None
    assert G.nd_geometry((2**24, 2, 2)) is None  # gridDim.z
    assert G.nd_geometry((70000, 2, 2)) == ((1, 1, 1094), (2, 2, 64))
    plan = FastPlan(2, ((0, 2, 4), (1, 2, 4)), (0,), (1,))
    rows, cols = 2**24, 2
    args = _jacobi_args(rows, cols)
    assert G.fast_geometry(plan, args, (rows, cols), rows * cols) is None


def test_a_launch_of_another_rank_keeps_the_general_entry():
    args = _jacobi_args(8, 8)
    assert G.fast_geometry(JACOBI_PLAN, args, (64,), 64) is None


def test_kernel_geometry_falls_back_to_the_linear_grid():
    k = cuda_backend.CudaKernel.__new__(cuda_backend.CudaKernel)
    k.plan = JACOBI_PLAN
    fast, geo = k.geometry(_jacobi_args(64, 64, same=True), (64, 64), 4096)
    assert not fast and geo == ((16, 1, 1), (256, 1, 1))
    fast, geo = k.geometry(_jacobi_args(64, 64), (64, 64), 4096)
    assert fast and geo == ((1, 16, 1), (64, 4, 1))
    k.plan = None
    assert k.geometry(_jacobi_args(64, 64), (64, 64), 4096) == (False, ((16, 1, 1), (256, 1, 1)))


# -- on a GPU ------------------------------------------------------------------------------
DEVICE = "cuda:0"


@pytest.fixture
def picks(monkeypatch):
    """``picks(kernel)``: whether each cuda launch of ``kernel`` took the fast entry."""
    seen: list[tuple[str, bool]] = []
    real = cuda_backend.CudaKernel.geometry

    def spy(self, args, dims, total):
        fast, geo = real(self, args, dims, total)
        seen.append((self.job.symbol, fast))
        return fast, geo

    monkeypatch.setattr(cuda_backend.CudaKernel, "geometry", spy)
    return lambda kernel: [fast for symbol, fast in seen if symbol == kernel.key]


def _general_only(monkeypatch) -> None:
    monkeypatch.setattr(cuda_backend, "fast_geometry", lambda *a: None)


def _run_jacobi(u: np.ndarray, device: str) -> np.ndarray:
    a = wp.array(u, dtype=float, device=device)
    out = wp.zeros(u.shape, dtype=float, device=device)
    wp.launch(jacobi, dim=u.shape, inputs=[a, out], device=device)
    return out.numpy()


_SHAPES = [(1, 1), (1, 700), (700, 1), (2, 2), (3, 5), (37, 291), (300, 257), (513, 1025)]


@needs_gpu
@pytest.mark.parametrize("shape", _SHAPES)
def test_jacobi_fast_entry_matches_general_and_cpu(shape, picks, monkeypatch):
    u = np.random.default_rng(1).normal(size=shape).astype(np.float32)
    fast = _run_jacobi(u, DEVICE)
    assert picks(jacobi) == [True]
    want = _run_jacobi(u, "cpu")
    np.testing.assert_array_equal(fast.view(np.uint32), want.view(np.uint32))
    _general_only(monkeypatch)
    general = _run_jacobi(u, DEVICE)
    assert picks(jacobi) == [True, False]
    np.testing.assert_array_equal(fast.view(np.uint32), general.view(np.uint32))


@needs_gpu
@pytest.mark.parametrize("shape", [(1, 1, 1), (2, 3, 5), (5, 7, 300), (70, 3, 2), (1, 513, 1)])
def test_3d_fast_entry_matches_cpu(shape, picks):
    u = np.random.default_rng(2).normal(size=shape).astype(np.float32)
    got = {}
    for device in (DEVICE, "cpu"):
        a = wp.array(u, dtype=float, device=device)
        out = wp.zeros(shape, dtype=float, device=device)
        wp.launch(smooth3, dim=shape, inputs=[a, out], device=device)
        got[device] = out.numpy()
    assert picks(smooth3) == [True]
    np.testing.assert_array_equal(got[DEVICE].view(np.uint32), got["cpu"].view(np.uint32))


@needs_gpu
def test_gather_fast_entry_matches_cpu(picks):
    rng = np.random.default_rng(3)
    n = 1001
    x = rng.normal(size=(n, 3)).astype(np.float32)
    idx = rng.integers(0, n, n).astype(np.int32)
    flags = rng.integers(0, 2, n).astype(bool)
    got = {}
    for device in (DEVICE, "cpu"):
        out = wp.zeros(n, dtype=wp.vec3, device=device)
        args = [wp.array(x, dtype=wp.vec3, device=device), wp.array(idx, dtype=int, device=device),
                wp.array(flags, dtype=wp.bool, device=device), out]  # fmt: skip
        wp.launch(gather_vec, dim=n, inputs=args, device=device)
        got[device] = out.numpy()
    assert picks(gather_vec) == [True]
    np.testing.assert_array_equal(got[DEVICE].view(np.uint32), got["cpu"].view(np.uint32))


@needs_gpu
def test_aliased_launch_takes_the_general_entry(picks):
    a = wp.array(np.arange(300, dtype=np.float32), device=DEVICE)
    wp.launch(copy_shift, dim=299, inputs=[a, a], device=DEVICE)
    assert picks(copy_shift) == [False]
    np.testing.assert_array_equal(a.numpy()[:299], np.arange(299, dtype=np.float32) + 1)
    b = wp.zeros(300, dtype=float, device=DEVICE)
    wp.launch(copy_shift, dim=300, inputs=[a, b], device=DEVICE)
    assert picks(copy_shift) == [False, True]


@needs_gpu
def test_prepared_and_captured_launches_take_the_fast_entry(picks):
    u = np.random.default_rng(4).normal(size=(65, 129)).astype(np.float32)
    a = wp.array(u, dtype=float, device=DEVICE)
    out = wp.zeros(u.shape, dtype=float, device=DEVICE)
    cmd = wp.launch(jacobi, dim=u.shape, inputs=[a, out], device=DEVICE, record_cmd=True)
    cmd.launch()
    with wp.ScopedCapture(device=DEVICE) as cap:
        wp.launch(jacobi, dim=u.shape, inputs=[a, out], device=DEVICE)
    wp.capture_launch(cap.graph)
    assert picks(jacobi) and all(picks(jacobi))
    np.testing.assert_array_equal(
        out.numpy().view(np.uint32), _run_jacobi(u, "cpu").view(np.uint32)
    )


@wp.kernel
def step_vec(x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3), x_out: wp.array(dtype=wp.vec3),
             v_out: wp.array(dtype=wp.vec3), grid: int, k: float, gravity: wp.vec3, dt: float):  # fmt: skip
    """Cloth's signature: vec3 arrays read and written, scalars and a vector by value."""
    i = wp.tid()
    r = i // grid
    j = wp.min(i + 1, x.shape[0] - 1)
    v1 = v[i] + (k * (x[j] - x[i]) + gravity * float(r)) * dt
    v_out[i] = v1
    x_out[i] = x[i] + v1 * dt


@needs_gpu
def test_cloth_like_launches_take_the_fast_entry(picks):
    rng = np.random.default_rng(5)
    n = 4097
    x = rng.normal(size=(n, 3)).astype(np.float32)
    v = rng.normal(size=(n, 3)).astype(np.float32)
    got = {}
    for device in (DEVICE, "cpu"):
        outs = [wp.zeros(n, dtype=wp.vec3, device=device) for _ in range(2)]
        args = [wp.array(x, dtype=wp.vec3, device=device), wp.array(v, dtype=wp.vec3, device=device),
                *outs, 64, 0.5, wp.vec3(0.0, -9.8, 0.0), 0.01]  # fmt: skip
        wp.launch(step_vec, dim=n, inputs=args, device=device)
        if device == DEVICE:
            cmd = wp.launch(step_vec, dim=n, inputs=args, device=device, record_cmd=True)
            cmd.launch()
            with wp.ScopedCapture(device=DEVICE) as cap:
                wp.launch(step_vec, dim=n, inputs=args, device=device)
            wp.capture_launch(cap.graph)
        got[device] = [o.numpy() for o in outs]
    assert picks(step_vec) and all(picks(step_vec))
    for a, b in zip(got[DEVICE], got["cpu"]):
        np.testing.assert_array_equal(a.view(np.uint32), b.view(np.uint32))
