"""The workloads in Numba (``@njit(parallel=True)`` with ``prange``); imported only when
selected. CPU only. Calls return when the parallel loop has finished.

Scalars are passed as ``np.float32`` and constants written as ``np.float32`` so the
loops stay in float32 like the other frameworks (a Python float would promote them).
"""

from __future__ import annotations

from collections.abc import Callable

import numba
import numpy as np
from numba import njit, prange

from .harness import Runner
from .workloads import LAUNCHES_PER_REP, Inputs

NAME = "numba"
F = np.float32


def version() -> str:
    """Numba's version string."""
    return numba.__version__


@njit(parallel=True)
def saxpy_kernel(x, y, a):
    for i in prange(x.shape[0]):
        y[i] = a * x[i] + y[i]


@njit(parallel=True)
def triad_kernel(a, b, c, s):
    for i in prange(a.shape[0]):
        a[i] = b[i] + s * c[i]


@njit(parallel=True)
def integrate_kernel(x, v, f, w, gravity, dt):
    for i in prange(x.shape[0]):
        for k in range(3):
            v1 = v[i, k] + (f[i, k] * w[i] + gravity[k]) * dt
            x[i, k] = x[i, k] + v1 * dt
            v[i, k] = v1


def _make_nbody(fastmath: bool) -> Callable:
    @njit(parallel=True, fastmath=fastmath)
    def accelerations(pos, mass, acc, eps2):
        n = pos.shape[0]
        one = np.float32(1.0)
        for i in prange(n):
            px, py, pz = pos[i, 0], pos[i, 1], pos[i, 2]
            ax = ay = az = np.float32(0.0)
            for j in range(n):
                dx, dy, dz = pos[j, 0] - px, pos[j, 1] - py, pos[j, 2] - pz
                inv_r = one / np.sqrt(dx * dx + dy * dy + dz * dz + eps2)
                s = mass[j] * inv_r * inv_r * inv_r
                ax += dx * s
                ay += dy * s
                az += dz * s
            acc[i, 0], acc[i, 1], acc[i, 2] = ax, ay, az

    return accelerations


nbody_kernel = _make_nbody(False)
nbody_fast_kernel = _make_nbody(True)


@njit(parallel=True)
def jacobi_kernel(u, out):
    n, m = u.shape
    quarter = np.float32(0.25)
    for i in prange(n):
        if i == 0 or i == n - 1:
            out[i, :] = u[i, :]
            continue
        out[i, 0] = u[i, 0]
        for j in range(1, m - 1):
            out[i, j] = quarter * (u[i - 1, j] + u[i + 1, j] + u[i, j - 1] + u[i, j + 1])
        out[i, m - 1] = u[i, m - 1]


@njit(parallel=True)
def cloth_kernel(x, v, x_out, v_out, grid, spacing, k, inv_mass, gravity, dt):
    diag = spacing * np.float32(1.4142135623730951)
    for tid in prange(x.shape[0]):
        r, c = tid // grid, tid % grid
        fx = fy = fz = np.float32(0.0)
        for dr in range(-1, 2):
            for dc in range(-1, 2):
                rr, cc = r + dr, c + dc
                if (dr == 0 and dc == 0) or rr < 0 or rr >= grid or cc < 0 or cc >= grid:
                    continue
                rest = diag if dr != 0 and dc != 0 else spacing
                j = rr * grid + cc
                dx, dy, dz = x[j, 0] - x[tid, 0], x[j, 1] - x[tid, 1], x[j, 2] - x[tid, 2]
                length = np.sqrt(dx * dx + dy * dy + dz * dz)
                if length > 0:
                    s = k * (length - rest) / length
                    fx += dx * s
                    fy += dy * s
                    fz += dz * s
        f = (fx, fy, fz)
        for q in range(3):
            v1 = v[tid, q] + (f[q] * inv_mass + gravity[q]) * dt
            v_out[tid, q] = v1
            x_out[tid, q] = x[tid, q] + v1 * dt


@njit(parallel=True)
def tiny_kernel(a, b):
    for _ in prange(1):
        b[0] = a[0] + np.float32(1.0)


def saxpy(ins: Inputs, device: str = "cpu") -> Runner:
    """y = a*x + y in place."""
    x, y, a = ins["x"].copy(), ins["y"].copy(), F(ins["a"])
    return Runner(lambda: saxpy_kernel(x, y, a), lambda: {"y": y.copy()})


def triad(n: int) -> tuple[Runner, int]:
    """The STREAM triad on ``n`` floats; gives the runner and the bytes one step moves."""
    rng = np.random.default_rng(0)
    a = np.zeros(n, np.float32)
    b, c = rng.random(n, dtype=np.float32), rng.random(n, dtype=np.float32)
    s = F(3.0)
    return Runner(lambda: triad_kernel(a, b, c, s), lambda: {"a": a.copy()}), 12 * n


def particles(ins: Inputs, device: str = "cpu") -> Runner:
    """The seeds' integrate kernel, in place."""
    x, v, f, w = (ins[k].copy() for k in ("x", "v", "f", "w"))
    g, dt = ins["gravity"].copy(), F(ins["dt"])
    return Runner(
        lambda: integrate_kernel(x, v, f, w, g, dt), lambda: {"x": x.copy(), "v": v.copy()}
    )


def nbody(ins: Inputs, device: str = "cpu", fast_math: bool = False) -> Runner:
    """All-pairs accelerations, ``fastmath`` as asked."""
    kernel = nbody_fast_kernel if fast_math else nbody_kernel
    pos, mass, eps2 = ins["pos"].copy(), ins["mass"].copy(), F(ins["eps2"])
    acc = np.zeros_like(pos)
    return Runner(lambda: kernel(pos, mass, acc, eps2), lambda: {"acc": acc.copy()})


def jacobi(ins: Inputs, device: str = "cpu") -> Runner:
    """One Jacobi sweep u -> out."""
    u = ins["u"].copy()
    out = np.zeros_like(u)
    return Runner(lambda: jacobi_kernel(u, out), lambda: {"out": out.copy()})


def cloth(ins: Inputs, device: str = "cpu") -> Runner:
    """One cloth step x, v -> x_out, v_out."""
    x, v = ins["x"].copy(), ins["v"].copy()
    x_out, v_out = np.zeros_like(x), np.zeros_like(v)
    args = (x, v, x_out, v_out, np.int64(ins["grid"]), F(ins["spacing"]), F(ins["stiffness"]),
            F(ins["inv_mass"]), ins["gravity"].copy(), F(ins["dt"]))  # fmt: skip
    return Runner(
        lambda: cloth_kernel(*args), lambda: {"x_out": x_out.copy(), "v_out": v_out.copy()}
    )


def launch(ins: Inputs, device: str = "cpu") -> Runner:
    """``LAUNCHES_PER_REP`` calls of a one-iteration parallel loop on two arrays."""
    a, b = ins["a"].copy(), ins["b"].copy()

    def step() -> None:
        for _ in range(LAUNCHES_PER_REP):
            tiny_kernel(a, b)

    return Runner(step, lambda: {"b": b.copy()}, LAUNCHES_PER_REP)


RUNNERS = {
    "saxpy": saxpy, "particles": particles, "nbody": nbody,
    "nbody_fast": lambda ins, device="cpu": nbody(ins, device, fast_math=True),
    "jacobi": jacobi, "cloth": cloth, "launch": launch,
}  # fmt: skip

START_SCRIPT = """
import time
import json
import numpy as np
import numba
from numba import njit, prange
t_import = time.perf_counter()

@njit(parallel=True, cache=True)
def accelerations(pos, mass, acc, eps2):
    n = pos.shape[0]
    one = np.float32(1.0)
    for i in prange(n):
        px, py, pz = pos[i, 0], pos[i, 1], pos[i, 2]
        ax = ay = az = np.float32(0.0)
        for j in range(n):
            dx, dy, dz = pos[j, 0] - px, pos[j, 1] - py, pos[j, 2] - pz
            inv_r = one / np.sqrt(dx * dx + dy * dy + dz * dz + eps2)
            s = mass[j] * inv_r * inv_r * inv_r
            ax += dx * s
            ay += dy * s
            az += dz * s
        acc[i, 0], acc[i, 1], acc[i, 2] = ax, ay, az

rng = np.random.default_rng(0)
n = {bodies}
pos = rng.normal(size=(n, 3)).astype(np.float32)
mass = np.ones(n, np.float32)
acc = np.zeros((n, 3), np.float32)
t0 = time.perf_counter()
accelerations(pos, mass, acc, np.float32(0.01))
t1 = time.perf_counter()
first_epoch = time.time()
accelerations(pos, mass, acc, np.float32(0.01))
t2 = time.perf_counter()
print(json.dumps({{"first_epoch": first_epoch, "after_import_s": t1 - t_import,
                  "compile_s": (t1 - t0) - (t2 - t1), "first_s": t1 - t0}}))
"""


def start_script(cache_dir: str, bodies: int, device: str = "cpu") -> tuple[str, dict[str, str]]:
    """The fresh-process n-body script (Numba's on-disk cache in ``cache_dir``)."""
    return START_SCRIPT.format(bodies=bodies), {"NUMBA_CACHE_DIR": cache_dir}
