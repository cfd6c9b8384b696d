"""The workloads in NVIDIA Warp (the peer kdsl's API follows); imported only when selected.

Warp's CPU launches are synchronous. On CUDA they go to Warp's current stream of the
device; the runner's ``sync`` is ``wp.synchronize_device`` and ``fetch`` goes through
``numpy()``, which synchronizes. The fast-math n-body kernel lives in its own module
(``module="unique"``) because ``fast_math`` is a module option in Warp.
"""

from typing import Any

import numpy as np
import warp as wp

from .harness import Runner
from .workloads import LAUNCHES_PER_REP, Inputs

NAME = "warp"

wp.config.quiet = True
wp.init()


def version() -> str:
    """Warp's version string."""
    return wp.config.version


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
        inv_r = 1.0 / wp.sqrt(wp.dot(d, d) + eps2)
        a += d * (mass[j] * inv_r * inv_r * inv_r)
    acc[i] = a


nbody_kernel = wp.kernel(_accelerations, module="unique", module_options={"fast_math": False})
nbody_fast_kernel = wp.kernel(_accelerations, module="unique", module_options={"fast_math": True})


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
):
    if r < 0 or r >= grid or c < 0 or c >= grid:
        return wp.vec3(0.0)
    d = x[r * grid + c] - xi
    length = wp.length(d)
    if length > 0.0:
        return d * (k * (length - rest) / length)
    return wp.vec3(0.0)


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
    f = wp.vec3(0.0)
    for dr in range(-1, 2):
        for dc in range(-1, 2):
            if dr != 0 or dc != 0:
                rest = spacing
                if dr != 0 and dc != 0:
                    rest = diag
                f += spring_force(x, xi, r + dr, c + dc, grid, rest, k)
    v1 = v[tid] + (f * inv_mass + gravity) * dt
    v_out[tid] = v1
    x_out[tid] = xi + v1 * dt


@wp.kernel
def tiny_kernel(a: wp.array(dtype=float), b: wp.array(dtype=float)):
    b[0] = a[0] + 1.0


def _arr(a: np.ndarray, device: str, dtype: Any = float) -> Any:
    return wp.array(a, dtype=dtype, device=device)


def _sync(device: str) -> Any:
    """Waits for Warp's work on ``device``; None on the CPU (launches are synchronous)."""
    if wp.get_device(device).is_cpu:
        return None
    return lambda: wp.synchronize_device(device)


def _runner(kernel: Any, dim: Any, args: list, outs: dict[str, Any], device: str) -> Runner:
    def step() -> None:
        wp.launch(kernel, dim=dim, inputs=args, device=device)

    def fetch() -> dict[str, np.ndarray]:
        return {k: v.numpy() for k, v in outs.items()}

    return Runner(step, fetch, sync=_sync(device))


def saxpy(ins: Inputs, device: str = "cpu") -> Runner:
    """y = a*x + y in place."""
    x, y = _arr(ins["x"], device), _arr(ins["y"], device)
    return _runner(saxpy_kernel, len(ins["x"]), [x, y, ins["a"]], {"y": y}, device)


def particles(ins: Inputs, device: str = "cpu") -> Runner:
    """The seeds' integrate kernel, in place."""
    x, v = _arr(ins["x"], device, wp.vec3), _arr(ins["v"], device, wp.vec3)
    args = [x, v, _arr(ins["f"], device, wp.vec3), _arr(ins["w"], device),
            wp.vec3(*ins["gravity"]), ins["dt"]]  # fmt: skip
    return _runner(integrate_kernel, len(ins["x"]), args, {"x": x, "v": v}, device)


def nbody(ins: Inputs, device: str = "cpu", fast_math: bool = False) -> Runner:
    """All-pairs accelerations, with or without Warp's fast_math module option."""
    kernel = nbody_fast_kernel if fast_math else nbody_kernel
    acc = wp.zeros(len(ins["pos"]), dtype=wp.vec3, device=device)
    args = [_arr(ins["pos"], device, wp.vec3), _arr(ins["mass"], device), acc, ins["eps2"]]
    return _runner(kernel, len(ins["pos"]), args, {"acc": acc}, device)


def jacobi(ins: Inputs, device: str = "cpu") -> Runner:
    """One Jacobi sweep u -> out over a 2-d launch."""
    u = _arr(ins["u"], device)
    out = wp.zeros(ins["u"].shape, dtype=float, device=device)
    return _runner(jacobi_kernel, ins["u"].shape, [u, out], {"out": out}, device)


def cloth(ins: Inputs, device: str = "cpu") -> Runner:
    """One cloth step x, v -> x_out, v_out."""
    n = len(ins["x"])
    x_out = wp.zeros(n, dtype=wp.vec3, device=device)
    v_out = wp.zeros(n, dtype=wp.vec3, device=device)
    args = [_arr(ins["x"], device, wp.vec3), _arr(ins["v"], device, wp.vec3), x_out, v_out,
            ins["grid"], ins["spacing"], ins["stiffness"], ins["inv_mass"],
            wp.vec3(*ins["gravity"]), ins["dt"]]  # fmt: skip
    return _runner(cloth_kernel, n, args, {"x_out": x_out, "v_out": v_out}, device)


def launch(ins: Inputs, device: str = "cpu") -> Runner:
    """``LAUNCHES_PER_REP`` plain ``wp.launch`` calls of a dim=1 kernel (then one sync)."""
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


RUNNERS = {
    "saxpy": saxpy, "particles": particles, "nbody": nbody,
    "nbody_fast": lambda ins, device="cpu": nbody(ins, device, fast_math=True),
    "jacobi": jacobi, "cloth": cloth, "launch": launch, "launch_prepared": launch_prepared,
}  # fmt: skip

START_SCRIPT = """
import time
import json
import numpy as np
import warp as wp
t_import = time.perf_counter()
wp.config.quiet = True
wp.config.kernel_cache_dir = {cache_dir!r}
wp.init()

@wp.kernel
def accelerations(pos: wp.array(dtype=wp.vec3), mass: wp.array(dtype=float),
                  acc: wp.array(dtype=wp.vec3), eps2: float):
    i = wp.tid()
    p = pos[i]
    a = wp.vec3(0.0, 0.0, 0.0)
    for j in range(pos.shape[0]):
        d = pos[j] - p
        inv_r = 1.0 / wp.sqrt(wp.dot(d, d) + eps2)
        a += d * (mass[j] * inv_r * inv_r * inv_r)
    acc[i] = a

rng = np.random.default_rng(0)
n = {bodies}
pos = wp.array(rng.normal(size=(n, 3)).astype(np.float32), dtype=wp.vec3, device="{device}")
mass = wp.array(np.ones(n, np.float32), dtype=float, device="{device}")
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
    """The fresh-process n-body script (Warp's kernel cache in ``cache_dir``)."""
    return START_SCRIPT.format(cache_dir=cache_dir, bodies=bodies, device=device), {}
