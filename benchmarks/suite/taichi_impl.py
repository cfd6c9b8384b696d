"""The workloads in Taichi (``ti.cpu``, or ``ti.cuda`` for a "cuda" device); imported
only when selected.

Kernels take ``ti.types.ndarray`` arguments; the data lives in Taichi ndarrays
(copied from the NumPy inputs once, so a step passes no external arrays). On the
CPU every step ends with ``ti.sync()`` so the timed region covers the kernel; on
CUDA the step only launches and ``ti.sync()`` is the runner's ``sync``. Taichi's fast math is a process-wide ``ti.init`` setting: ``init``
re-initializes Taichi when a row needs the other setting (kernels recompile on
their next call); bench_cpu runs the IEEE rows first and the fast-math n-body last.
"""

import numpy as np
import taichi as ti

from .harness import Runner
from .workloads import LAUNCHES_PER_REP, Inputs

NAME = "taichi"

_state: dict[str, object] = {"fast_math": None, "arch": None}

vec3 = ti.math.vec3
F32 = ti.types.ndarray(dtype=ti.f32, ndim=1)
V3 = ti.types.ndarray(dtype=vec3, ndim=1)
F32_2D = ti.types.ndarray(dtype=ti.f32, ndim=2)


def version() -> str:
    """Taichi's version string."""
    return ".".join(map(str, ti.__version__))


def init(fast_math: bool, device: str = "cpu") -> None:
    """``ti.init`` for ``device`` with ``fast_math``, unless already so initialized."""
    arch = ti.cpu if device == "cpu" else ti.cuda
    if _state["fast_math"] == fast_math and _state["arch"] == device:
        return
    ti.init(arch=arch, fast_math=fast_math, log_level=ti.WARN)
    _state.update(fast_math=fast_math, arch=device)


@ti.kernel
def saxpy_kernel(x: F32, y: F32, a: ti.f32):
    for i in x:
        y[i] = a * x[i] + y[i]


@ti.kernel
def integrate_kernel(x: V3, v: V3, f: V3, w: F32, gravity: vec3, dt: ti.f32):
    for i in x:
        v1 = v[i] + (f[i] * w[i] + gravity) * dt
        x[i] = x[i] + v1 * dt
        v[i] = v1


@ti.kernel
def nbody_kernel(pos: V3, mass: F32, acc: V3, eps2: ti.f32):
    n = pos.shape[0]
    for i in range(n):
        p = pos[i]
        a = vec3(0.0)
        for j in range(n):
            d = pos[j] - p
            inv_r = 1.0 / ti.sqrt(d.dot(d) + eps2)
            a += d * (mass[j] * inv_r * inv_r * inv_r)
        acc[i] = a


@ti.kernel
def jacobi_kernel(u: F32_2D, out: F32_2D):
    n, m = u.shape[0], u.shape[1]
    for i, j in ti.ndrange(n, m):
        if i == 0 or j == 0 or i == n - 1 or j == m - 1:
            out[i, j] = u[i, j]
        else:
            out[i, j] = 0.25 * (u[i - 1, j] + u[i + 1, j] + u[i, j - 1] + u[i, j + 1])


@ti.kernel
def cloth_kernel(
    x: V3, v: V3, x_out: V3, v_out: V3, grid: ti.i32, spacing: ti.f32, k: ti.f32,
    inv_mass: ti.f32, gravity: vec3, dt: ti.f32,
):  # fmt: skip
    for tid in x:
        r = tid // grid
        c = tid % grid
        xi = x[tid]
        f = vec3(0.0)
        for dr, dc in ti.static(ti.ndrange((-1, 2), (-1, 2))):
            if ti.static(dr != 0 or dc != 0):
                rest = spacing * ti.static(1.4142135623730951 if dr != 0 and dc != 0 else 1.0)
                rr, cc = r + dr, c + dc
                if 0 <= rr < grid and 0 <= cc < grid:
                    d = x[rr * grid + cc] - xi
                    length = d.norm()
                    if length > 0.0:
                        f += d * (k * (length - rest) / length)
        v1 = v[tid] + (f * inv_mass + gravity) * dt
        v_out[tid] = v1
        x_out[tid] = xi + v1 * dt


@ti.kernel
def tiny_kernel(a: F32, b: F32):
    b[0] = a[0] + 1.0


def _nd(a: np.ndarray):
    """A Taichi ndarray holding a copy of ``a`` ((n, 3) arrays become vec3 ndarrays)."""
    if a.ndim == 2 and a.shape[1] == 3 and a.dtype == np.float32:
        out = ti.Vector.ndarray(3, ti.f32, shape=a.shape[0])
    else:
        out = ti.ndarray(ti.f32, shape=a.shape)
    out.from_numpy(a)
    return out


def _runner(call, outs: dict) -> Runner:
    def fetch() -> dict:
        return {k: v.to_numpy() for k, v in outs.items()}

    if _state["arch"] != "cpu":
        return Runner(call, fetch, sync=ti.sync)

    def step() -> None:
        call()
        ti.sync()

    return Runner(step, fetch)


def saxpy(ins: Inputs, device: str = "cpu") -> Runner:
    """y = a*x + y in place."""
    init(False, device)
    x, y = _nd(ins["x"]), _nd(ins["y"])
    return _runner(lambda: saxpy_kernel(x, y, ins["a"]), {"y": y})


def particles(ins: Inputs, device: str = "cpu") -> Runner:
    """The seeds' integrate kernel, in place."""
    init(False, device)
    x, v, f, w = (_nd(ins[k]) for k in ("x", "v", "f", "w"))
    g = vec3(*ins["gravity"])
    return _runner(lambda: integrate_kernel(x, v, f, w, g, ins["dt"]), {"x": x, "v": v})


def nbody(ins: Inputs, device: str = "cpu", fast_math: bool = False) -> Runner:
    """All-pairs accelerations, with Taichi's default fast math or ``fast_math=False``."""
    init(fast_math, device)
    pos, mass = _nd(ins["pos"]), _nd(ins["mass"])
    acc = _nd(np.zeros_like(ins["pos"]))
    return _runner(lambda: nbody_kernel(pos, mass, acc, ins["eps2"]), {"acc": acc})


def jacobi(ins: Inputs, device: str = "cpu") -> Runner:
    """One Jacobi sweep u -> out."""
    init(False, device)
    u = _nd(ins["u"])
    out = _nd(np.zeros_like(ins["u"]))
    return _runner(lambda: jacobi_kernel(u, out), {"out": out})


def cloth(ins: Inputs, device: str = "cpu") -> Runner:
    """One cloth step x, v -> x_out, v_out."""
    init(False, device)
    x, v = _nd(ins["x"]), _nd(ins["v"])
    x_out, v_out = _nd(np.zeros_like(ins["x"])), _nd(np.zeros_like(ins["v"]))
    g = vec3(*ins["gravity"])

    def call() -> None:
        cloth_kernel(x, v, x_out, v_out, ins["grid"], ins["spacing"], ins["stiffness"],
                     ins["inv_mass"], g, ins["dt"])  # fmt: skip

    return _runner(call, {"x_out": x_out, "v_out": v_out})


def launch(ins: Inputs, device: str = "cpu") -> Runner:
    """``LAUNCHES_PER_REP`` calls of a one-thread kernel on two ndarrays (synced at the end)."""
    init(False, device)
    a, b = _nd(ins["a"]), _nd(ins["b"])

    def step() -> None:
        for _ in range(LAUNCHES_PER_REP):
            tiny_kernel(a, b)
        ti.sync()

    return Runner(step, lambda: {"b": b.to_numpy()}, LAUNCHES_PER_REP)


RUNNERS = {
    "saxpy": saxpy, "particles": particles, "nbody": nbody,
    "nbody_fast": lambda ins, device="cpu": nbody(ins, device, fast_math=True),
    "jacobi": jacobi, "cloth": cloth, "launch": launch,
}  # fmt: skip

START_SCRIPT = """
import time
import json
import numpy as np
import taichi as ti
t_import = time.perf_counter()
ti.init(arch=ti.{arch}, offline_cache=True, offline_cache_file_path={cache_dir!r},
        log_level=ti.WARN)
V3 = ti.types.ndarray(dtype=ti.math.vec3, ndim=1)

@ti.kernel
def accelerations(pos: V3, mass: ti.types.ndarray(dtype=ti.f32, ndim=1), acc: V3,
                  eps2: ti.f32):
    n = pos.shape[0]
    for i in range(n):
        p = pos[i]
        a = ti.math.vec3(0.0)
        for j in range(n):
            d = pos[j] - p
            inv_r = 1.0 / ti.sqrt(d.dot(d) + eps2)
            a += d * (mass[j] * inv_r * inv_r * inv_r)
        acc[i] = a

rng = np.random.default_rng(0)
n = {bodies}
pos = rng.normal(size=(n, 3)).astype(np.float32)
mass = np.ones(n, np.float32)
acc = np.zeros((n, 3), np.float32)
t0 = time.perf_counter()
accelerations(pos, mass, acc, 0.01)
ti.sync()
t1 = time.perf_counter()
first_epoch = time.time()
accelerations(pos, mass, acc, 0.01)
ti.sync()
t2 = time.perf_counter()
print(json.dumps({{"first_epoch": first_epoch, "after_import_s": t1 - t_import,
                  "compile_s": (t1 - t0) - (t2 - t1), "first_s": t1 - t0}}))
"""


def start_script(cache_dir: str, bodies: int, device: str = "cpu") -> tuple[str, dict[str, str]]:
    """The fresh-process n-body script (Taichi's offline cache in ``cache_dir``)."""
    arch = "cpu" if device == "cpu" else "cuda"
    return START_SCRIPT.format(arch=arch, cache_dir=cache_dir, bodies=bodies), {}
