"""The workloads as hand-written CUDA C kernels, compiled and launched by CuPy (``RawModule``).

The baseline a GPU programmer would write without a DSL: one thread per element
(2-d 32x8 blocks for the Jacobi grid), ``__restrict__`` pointers, float32 math,
vec3 data as packed ``float[3]``. The algorithms are the other frameworks' (the
n-body kernel is the plain all-pairs loop, not a shared-memory tiled one), so the
comparison is between code generators. NVRTC defaults are IEEE-exact (precise
division and square root, denormals kept); the fast-math n-body module is built
with ``--use_fast_math``, like the other frameworks' fast-math kernels.

Work goes to CuPy's current stream of the device (by default the legacy default
stream); a runner's ``sync`` waits for that stream. CUDA only.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import cupy
import numpy as np

from .harness import Runner
from .workloads import LAUNCHES_PER_REP, Inputs

NAME = "cupy"
BLOCK = 256

NBODY_SOURCE = r"""
extern "C" __global__ void accelerations(const float* __restrict__ pos,
                                         const float* __restrict__ mass,
                                         float* __restrict__ acc, float eps2, int n) {
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) return;
    float px = pos[3 * i], py = pos[3 * i + 1], pz = pos[3 * i + 2];
    float ax = 0.0f, ay = 0.0f, az = 0.0f;
    for (int j = 0; j < n; ++j) {
        float dx = pos[3 * j] - px, dy = pos[3 * j + 1] - py, dz = pos[3 * j + 2] - pz;
        float inv_r = 1.0f / sqrtf(dx * dx + dy * dy + dz * dz + eps2);
        float s = mass[j] * inv_r * inv_r * inv_r;
        ax += dx * s;
        ay += dy * s;
        az += dz * s;
    }
    acc[3 * i] = ax;
    acc[3 * i + 1] = ay;
    acc[3 * i + 2] = az;
}
"""

KERNELS_SOURCE = r"""
extern "C" __global__ void saxpy(const float* __restrict__ x, float* __restrict__ y,
                                 float a, int n) {
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i < n) y[i] = a * x[i] + y[i];
}

extern "C" __global__ void integrate(float* __restrict__ x, float* __restrict__ v,
                                     const float* __restrict__ f,
                                     const float* __restrict__ w,
                                     float gx, float gy, float gz, float dt, int n) {
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) return;
    const float g[3] = {gx, gy, gz};
    float wi = w[i];
#pragma unroll
    for (int k = 0; k < 3; ++k) {
        float v1 = v[3 * i + k] + (f[3 * i + k] * wi + g[k]) * dt;
        x[3 * i + k] += v1 * dt;
        v[3 * i + k] = v1;
    }
}

extern "C" __global__ void jacobi(const float* __restrict__ u, float* __restrict__ out,
                                  int rows, int cols) {
    int c = blockIdx.x * blockDim.x + threadIdx.x;
    int r = blockIdx.y * blockDim.y + threadIdx.y;
    if (r >= rows || c >= cols) return;
    int k = r * cols + c;
    if (r == 0 || c == 0 || r == rows - 1 || c == cols - 1)
        out[k] = u[k];
    else
        out[k] = 0.25f * (u[k - cols] + u[k + cols] + u[k - 1] + u[k + 1]);
}

extern "C" __global__ void cloth(const float* __restrict__ x, const float* __restrict__ v,
                                 float* __restrict__ x_out, float* __restrict__ v_out,
                                 int grid, float spacing, float k, float inv_mass,
                                 float gx, float gy, float gz, float dt) {
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= grid * grid) return;
    int r = i / grid, c = i - r * grid;
    float xx = x[3 * i], xy = x[3 * i + 1], xz = x[3 * i + 2];
    float diag = spacing * 1.4142135623730951f;
    float fx = 0.0f, fy = 0.0f, fz = 0.0f;
#pragma unroll
    for (int dr = -1; dr <= 1; ++dr) {
#pragma unroll
        for (int dc = -1; dc <= 1; ++dc) {
            int rr = r + dr, cc = c + dc;
            if ((dr == 0 && dc == 0) || rr < 0 || rr >= grid || cc < 0 || cc >= grid) continue;
            const float* xn = x + 3 * (rr * grid + cc);
            float dx = xn[0] - xx, dy = xn[1] - xy, dz = xn[2] - xz;
            float len = sqrtf(dx * dx + dy * dy + dz * dz);
            if (len > 0.0f) {
                float s = k * (len - (dr != 0 && dc != 0 ? diag : spacing)) / len;
                fx += dx * s;
                fy += dy * s;
                fz += dz * s;
            }
        }
    }
    float vx = v[3 * i] + (fx * inv_mass + gx) * dt;
    float vy = v[3 * i + 1] + (fy * inv_mass + gy) * dt;
    float vz = v[3 * i + 2] + (fz * inv_mass + gz) * dt;
    v_out[3 * i] = vx;
    v_out[3 * i + 1] = vy;
    v_out[3 * i + 2] = vz;
    x_out[3 * i] = xx + vx * dt;
    x_out[3 * i + 1] = xy + vy * dt;
    x_out[3 * i + 2] = xz + vz * dt;
}

extern "C" __global__ void tiny(const float* __restrict__ a, float* __restrict__ b) {
    b[0] = a[0] + 1.0f;
}
"""

#: The sources and NVRTC options of the modules, by name (also read by the NVRTC check).
MODULES = {
    "kernels": (KERNELS_SOURCE, ()),
    "nbody": (NBODY_SOURCE, ()),
    "nbody_fast": (NBODY_SOURCE, ("--use_fast_math",)),
}


def version() -> str:
    """CuPy's version and the CUDA runtime it runs on."""
    rt = cupy.cuda.runtime.runtimeGetVersion()
    return f"{cupy.__version__} (CUDA {rt // 1000}.{rt % 1000 // 10})"


@functools.cache
def _module(name: str, ordinal: int) -> Any:
    source, options = MODULES[name]
    with cupy.cuda.Device(ordinal):
        return cupy.RawModule(code=source, options=options)


def _kernel(module: str, name: str, device: str) -> Any:
    ordinal = _ordinal(device)
    cupy.cuda.Device(ordinal).use()  # later allocations and launches go to this device
    return _module(module, ordinal).get_function(name)


def _ordinal(device: str) -> int:
    kind, _, index = device.partition(":")
    if kind != "cuda":
        raise ValueError(f"the hand-written CUDA kernels need a cuda device, not {device!r}")
    return int(index or 0)


def _dev(a: np.ndarray) -> Any:
    return cupy.asarray(a)


def _sync() -> None:
    cupy.cuda.get_current_stream().synchronize()


def _blocks(n: int) -> tuple[int]:
    return ((n + BLOCK - 1) // BLOCK,)


def _runner(launch: Callable[[], None], outs: dict[str, Any]) -> Runner:
    return Runner(launch, lambda: {k: cupy.asnumpy(v) for k, v in outs.items()}, sync=_sync)


def saxpy(ins: Inputs, device: str = "cuda:0") -> Runner:
    """y = a*x + y in place."""
    kern = _kernel("kernels", "saxpy", device)
    x, y = _dev(ins["x"]), _dev(ins["y"])
    n = x.size
    args = (x, y, np.float32(ins["a"]), np.int32(n))
    return _runner(lambda: kern(_blocks(n), (BLOCK,), args), {"y": y})


def particles(ins: Inputs, device: str = "cuda:0") -> Runner:
    """The seeds' integrate kernel, in place."""
    kern = _kernel("kernels", "integrate", device)
    x, v, f, w = (_dev(ins[k]) for k in ("x", "v", "f", "w"))
    n = w.size
    g = [np.float32(c) for c in ins["gravity"]]
    args = (x, v, f, w, *g, np.float32(ins["dt"]), np.int32(n))
    return _runner(lambda: kern(_blocks(n), (BLOCK,), args), {"x": x, "v": v})


def nbody(ins: Inputs, device: str = "cuda:0", fast_math: bool = False) -> Runner:
    """All-pairs accelerations; ``fast_math`` uses the module built with ``--use_fast_math``."""
    kern = _kernel("nbody_fast" if fast_math else "nbody", "accelerations", device)
    pos, mass = _dev(ins["pos"]), _dev(ins["mass"])
    acc = cupy.zeros_like(pos)
    n = mass.size
    args = (pos, mass, acc, np.float32(ins["eps2"]), np.int32(n))
    return _runner(lambda: kern(_blocks(n), (BLOCK,), args), {"acc": acc})


def jacobi(ins: Inputs, device: str = "cuda:0") -> Runner:
    """One Jacobi sweep u -> out over a 2-d grid of 32x8 blocks."""
    kern = _kernel("kernels", "jacobi", device)
    u = _dev(ins["u"])
    out = cupy.zeros_like(u)
    rows, cols = u.shape
    grid = ((cols + 31) // 32, (rows + 7) // 8)
    args = (u, out, np.int32(rows), np.int32(cols))
    return _runner(lambda: kern(grid, (32, 8), args), {"out": out})


def cloth(ins: Inputs, device: str = "cuda:0") -> Runner:
    """One cloth step x, v -> x_out, v_out."""
    kern = _kernel("kernels", "cloth", device)
    x, v = _dev(ins["x"]), _dev(ins["v"])
    x_out, v_out = cupy.zeros_like(x), cupy.zeros_like(v)
    g = ins["grid"]
    f32 = np.float32
    args = (x, v, x_out, v_out, np.int32(g), f32(ins["spacing"]), f32(ins["stiffness"]),
            f32(ins["inv_mass"]), *(f32(c) for c in ins["gravity"]), f32(ins["dt"]))  # fmt: skip
    return _runner(lambda: kern(_blocks(g * g), (BLOCK,), args), {"x_out": x_out, "v_out": v_out})


def launch(ins: Inputs, device: str = "cuda:0") -> Runner:
    """``LAUNCHES_PER_REP`` ``RawKernel`` calls of a one-thread kernel (then one sync)."""
    kern = _kernel("kernels", "tiny", device)
    a, b = _dev(ins["a"]), _dev(ins["b"])
    args = (a, b)

    def step() -> None:
        for _ in range(LAUNCHES_PER_REP):
            kern((1,), (1,), args)
        _sync()

    return Runner(step, lambda: {"b": cupy.asnumpy(b)}, LAUNCHES_PER_REP)


def copy(ins: Inputs, device: str = "cuda:0") -> Runner:
    """A device-to-device ``cudaMemcpyAsync`` of x into y: the bandwidth yardstick."""
    cupy.cuda.Device(_ordinal(device)).use()
    x, y = _dev(ins["x"]), _dev(ins["y"])
    nbytes = x.nbytes

    def step() -> None:
        y.data.copy_from_device_async(x.data, nbytes)

    return _runner(step, {"y": y})


RUNNERS = {
    "saxpy": saxpy, "particles": particles, "nbody": nbody,
    "nbody_fast": lambda ins, device="cuda:0": nbody(ins, device, fast_math=True),
    "jacobi": jacobi, "cloth": cloth, "launch": launch, "copy": copy,
}  # fmt: skip

#: A fresh-process n-body: compiles the kernel (CuPy's disk cache in CUPY_CACHE_DIR)
#: and prints the same JSON as the other frameworks' start scripts.
START_SCRIPT = """
import time
import json
import numpy as np
import cupy
t_import = time.perf_counter()
source = {source!r}
rng = np.random.default_rng(0)
n = {bodies}
with cupy.cuda.Device({ordinal}):
    pos = cupy.asarray(rng.normal(size=(n, 3)).astype(np.float32))
    mass = cupy.ones(n, np.float32)
    acc = cupy.zeros((n, 3), np.float32)
    args = (pos, mass, acc, np.float32(0.01), np.int32(n))
    blocks = ((n + 255) // 256,)
    t0 = time.perf_counter()
    kern = cupy.RawKernel(source, "accelerations")
    kern(blocks, (256,), args)
    acc.get()
    t1 = time.perf_counter()
    first_epoch = time.time()
    kern(blocks, (256,), args)
    acc.get()
    t2 = time.perf_counter()
print(json.dumps({{"first_epoch": first_epoch, "after_import_s": t1 - t_import,
                  "compile_s": (t1 - t0) - (t2 - t1), "first_s": t1 - t0}}))
"""


def start_script(cache_dir: str, bodies: int, device: str = "cuda:0") -> tuple[str, dict[str, str]]:
    """The fresh-process n-body script (CuPy's kernel cache in ``cache_dir``)."""
    src = START_SCRIPT.format(source=NBODY_SOURCE, bodies=bodies, ordinal=_ordinal(device))
    return src, {"CUPY_CACHE_DIR": cache_dir}
