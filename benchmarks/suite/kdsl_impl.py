"""The workloads in kdsl: one function per workload, each returning a ``Runner``.

Every function takes the workload's inputs (``workloads``) and a ``device``
("cpu" or "cuda:0"). kdsl launches on the cpu backend return when the kernel has
finished. On CUDA they are enqueued on the device's current kdsl stream
(``kdsl.get_stream(device)``), which the runner's ``sync`` waits for;
``array.numpy()`` synchronizes too.
"""

from __future__ import annotations

from typing import Any

import numpy as np

import kdsl as wp

from .harness import Runner
from .workloads import LAUNCHES_PER_REP, Inputs

NAME = "kdsl"


def version() -> str:
    """kdsl's version string."""
    return getattr(wp, "__version__", "dev")


@wp.kernel
def saxpy_kernel(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
    i = wp.tid()
    y[i] = a * x[i] + y[i]


@wp.kernel
def integrate_kernel(
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    f: wp.array(dtype=wp.vec3),
    w: wp.array(dtype=float),
    gravity: wp.vec3,
    dt: float,
):
    tid = wp.tid()
    v1 = v[tid] + (f[tid] * w[tid] + gravity) * dt
    x[tid] = x[tid] + v1 * dt
    v[tid] = v1


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
        r2 = wp.dot(d, d) + eps2
        inv_r = 1.0 / wp.sqrt(r2)
        a = a + d * (mass[j] * inv_r * inv_r * inv_r)
    acc[i] = a


nbody_kernel = wp.kernel(_accelerations)
nbody_fast_kernel = wp.kernel(fast_math=True)(_accelerations)


@wp.kernel
def jacobi_kernel(u: wp.array2d(dtype=float), out: wp.array2d(dtype=float)):
    i, j = wp.tid()
    if i == 0 or j == 0 or i == u.shape[0] - 1 or j == u.shape[1] - 1:
        out[i, j] = u[i, j]
    else:
        out[i, j] = 0.25 * (u[i - 1, j] + u[i + 1, j] + u[i, j - 1] + u[i, j + 1])


@wp.func
def spring_force(
    x: wp.array(dtype=wp.vec3), xi: wp.vec3, r: int, c: int, grid: int, rest: float, k: float
) -> wp.vec3:
    # The pull of the spring to grid point (r, c); none where that point is off the grid.
    if r < 0 or r >= grid or c < 0 or c >= grid:
        return wp.vec3(0.0, 0.0, 0.0)
    d = x[r * grid + c] - xi
    length = wp.length(d)
    if length > 0.0:
        return d * (k * (length - rest) / length)
    return wp.vec3(0.0, 0.0, 0.0)


@wp.kernel
def cloth_kernel(
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    x_out: wp.array(dtype=wp.vec3),
    v_out: wp.array(dtype=wp.vec3),
    grid: int,
    spacing: float,
    k: float,
    inv_mass: float,
    gravity: wp.vec3,
    dt: float,
):
    tid = wp.tid()
    r = tid // grid
    c = tid - r * grid
    xi = x[tid]
    diag = spacing * 1.4142135623730951
    f = spring_force(x, xi, r - 1, c, grid, spacing, k)
    f = f + spring_force(x, xi, r + 1, c, grid, spacing, k)
    f = f + spring_force(x, xi, r, c - 1, grid, spacing, k)
    f = f + spring_force(x, xi, r, c + 1, grid, spacing, k)
    f = f + spring_force(x, xi, r - 1, c - 1, grid, diag, k)
    f = f + spring_force(x, xi, r - 1, c + 1, grid, diag, k)
    f = f + spring_force(x, xi, r + 1, c - 1, grid, diag, k)
    f = f + spring_force(x, xi, r + 1, c + 1, grid, diag, k)
    v1 = v[tid] + (f * inv_mass + gravity) * dt
    v_out[tid] = v1
    x_out[tid] = xi + v1 * dt


@wp.kernel
def tiny_kernel(a: wp.array(dtype=float), b: wp.array(dtype=float)):
    b[0] = a[0] + 1.0


def _vec3(a: np.ndarray, device: str) -> Any:
    return wp.from_numpy(a, dtype=wp.vec3, device=device)


def _arr(a: np.ndarray, device: str) -> Any:
    return wp.from_numpy(a, dtype=wp.float32, device=device)


def _sync(device: str) -> Any:
    """Waits for the kdsl stream that launches on ``device`` use; None on the CPU."""
    return None if wp.get_device(device).is_cpu else wp.get_stream(device).synchronize


def _runner(kernel: Any, dim: Any, args: list, outs: dict[str, Any], device: str) -> Runner:
    def step() -> None:
        wp.launch(kernel, dim=dim, inputs=args, device=device)

    return Runner(step, lambda: {k: v.numpy() for k, v in outs.items()}, sync=_sync(device))


def saxpy(ins: Inputs, device: str = "cpu") -> Runner:
    """y = a*x + y in place."""
    x, y = _arr(ins["x"], device), _arr(ins["y"], device)
    return _runner(saxpy_kernel, len(ins["x"]), [x, y, ins["a"]], {"y": y}, device)


def particles(ins: Inputs, device: str = "cpu") -> Runner:
    """The seeds' integrate kernel, in place."""
    x, v = _vec3(ins["x"], device), _vec3(ins["v"], device)
    args = [x, v, _vec3(ins["f"], device), _arr(ins["w"], device),
            wp.vec3(*ins["gravity"]), ins["dt"]]  # fmt: skip
    return _runner(integrate_kernel, len(ins["x"]), args, {"x": x, "v": v}, device)


def nbody(ins: Inputs, device: str = "cpu", fast_math: bool = False) -> Runner:
    """All-pairs accelerations; ``fast_math`` uses the kernel built with that option."""
    kernel = nbody_fast_kernel if fast_math else nbody_kernel
    acc = wp.zeros(len(ins["pos"]), dtype=wp.vec3, device=device)
    args = [_vec3(ins["pos"], device), _arr(ins["mass"], device), acc, ins["eps2"]]
    return _runner(kernel, len(ins["pos"]), args, {"acc": acc}, device)


def jacobi(ins: Inputs, device: str = "cpu") -> Runner:
    """One Jacobi sweep u -> out over a 2-d launch."""
    u = _arr(ins["u"], device)
    out = wp.zeros(ins["u"].shape, dtype=wp.float32, device=device)
    return _runner(jacobi_kernel, ins["u"].shape, [u, out], {"out": out}, device)


def cloth(ins: Inputs, device: str = "cpu") -> Runner:
    """One cloth step x, v -> x_out, v_out."""
    n = len(ins["x"])
    x_out = wp.zeros(n, dtype=wp.vec3, device=device)
    v_out = wp.zeros(n, dtype=wp.vec3, device=device)
    args = [_vec3(ins["x"], device), _vec3(ins["v"], device), x_out, v_out, ins["grid"],
            ins["spacing"], ins["stiffness"], ins["inv_mass"], wp.vec3(*ins["gravity"]),
            ins["dt"]]  # fmt: skip
    return _runner(cloth_kernel, n, args, {"x_out": x_out, "v_out": v_out}, device)


def launch(ins: Inputs, device: str = "cpu") -> Runner:
    """``LAUNCHES_PER_REP`` plain ``kdsl.launch`` calls of a dim=1 kernel (then one sync)."""
    a, b = _arr(ins["a"], device), _arr(ins["b"], device)
    sync = _sync(device)

    def step() -> None:
        for _ in range(LAUNCHES_PER_REP):
            wp.launch(tiny_kernel, dim=1, inputs=[a, b], device=device)
        if sync is not None:
            sync()

    return Runner(step, lambda: {"b": b.numpy()}, LAUNCHES_PER_REP)


def launch_prepared(ins: Inputs, device: str = "cpu") -> Runner:
    """``LAUNCHES_PER_REP`` calls of a launch recorded with ``record_cmd=True``."""
    a, b = _arr(ins["a"], device), _arr(ins["b"], device)
    cmd = wp.launch(tiny_kernel, dim=1, inputs=[a, b], device=device, record_cmd=True)
    sync = _sync(device)

    def step() -> None:
        run = cmd.launch
        for _ in range(LAUNCHES_PER_REP):
            run()
        if sync is not None:
            sync()

    return Runner(step, lambda: {"b": b.numpy()}, LAUNCHES_PER_REP)


def set_threads(n: int | None) -> None:
    """Use ``n`` cpu threads (None: the default)."""
    from kdsl.backends.cpu import set_num_threads

    set_num_threads(n)


RUNNERS = {
    "saxpy": saxpy, "particles": particles, "nbody": nbody,
    "nbody_fast": lambda ins, device="cpu": nbody(ins, device, fast_math=True),
    "jacobi": jacobi, "cloth": cloth, "launch": launch, "launch_prepared": launch_prepared,
}  # fmt: skip

#: A fresh-process n-body: ``{bodies}`` and ``{device}`` are filled in; it prints JSON
#: with the epoch of the first result, the time from after import to it, and the
#: compile (first launch minus a second, warm one).
START_SCRIPT = """
import time
import json
import numpy as np
import kdsl as wp
t_import = time.perf_counter()

@wp.kernel
def accelerations(pos: wp.array(dtype=wp.vec3), mass: wp.array(dtype=float),
                  acc: wp.array(dtype=wp.vec3), eps2: float):
    i = wp.tid()
    p = pos[i]
    a = wp.vec3(0.0, 0.0, 0.0)
    for j in range(pos.shape[0]):
        d = pos[j] - p
        r2 = wp.dot(d, d) + eps2
        inv_r = 1.0 / wp.sqrt(r2)
        a = a + d * (mass[j] * inv_r * inv_r * inv_r)
    acc[i] = a

rng = np.random.default_rng(0)
n = {bodies}
pos = wp.from_numpy(rng.normal(size=(n, 3)).astype(np.float32), dtype=wp.vec3, device="{device}")
mass = wp.from_numpy(np.ones(n, np.float32), dtype=wp.float32, device="{device}")
acc = wp.zeros(n, dtype=wp.vec3, device="{device}")
t0 = time.perf_counter()
wp.launch(accelerations, dim=n, inputs=[pos, mass, acc, 0.01], device="{device}")
acc.numpy()
t1 = time.perf_counter()
first_epoch = time.time()
wp.launch(accelerations, dim=n, inputs=[pos, mass, acc, 0.01], device="{device}")
acc.numpy()
t2 = time.perf_counter()
print(json.dumps({{"first_epoch": first_epoch, "after_import_s": t1 - t_import,
                  "compile_s": (t1 - t0) - (t2 - t1), "first_s": t1 - t0}}))
"""


def start_script(cache_dir: str, bodies: int, device: str = "cpu") -> tuple[str, dict[str, str]]:
    """The fresh-process n-body script and its environment (kernel cache in ``cache_dir``)."""
    return START_SCRIPT.format(bodies=bodies, device=device), {"KDSL_CACHE_DIR": cache_dir}
