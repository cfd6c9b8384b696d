"""Each scene's step under kdsl beside the same scene file run with NVIDIA Warp.

    python benchmarks/bench_scenes.py [--device cpu|cuda] [--reps 7] [--scenes a,b]
                                      [--no-compile] [--thread-time] [--json PATH]

The scene files of ``kdsl.scenes`` are bound to kdsl (``bind("kdsl")``) and to Warp
(``bind("warp")``) and run on the same device, float32, with the benchmark sizes of
``SIZES`` (larger than the scenes' defaults, so the step is work, not launch
overhead). A step's time is the median over ``--reps`` repetitions of ``steps``
steps (device synchronized around them), after one untimed repetition (the compile).
``--thread-time`` times the calling thread's CPU seconds instead of the wall clock:
with ``KDSL_CPU_THREADS=1`` kdsl runs every kernel on that thread, as Warp's cpu
kernels do, so it compares the two per core, which a host shared with other jobs
disturbs far less than the wall clock (the process's CPU time would also count other
threads, such as OpenBLAS's spinning workers).

Cold compile: in a fresh process per framework and scene, with its kernel cache
pointed at an empty directory (``KDSL_CACHE=0``; ``WARP_CACHE_PATH`` at a new
temporary directory), the time of the first step (what it launches compiles): kdsl
compiles each kernel it launches, forward only; Warp builds each launched kernel's
module, forward and adjoint. Results go to benchmarks/results/scenes.json.
"""

import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from suite import harness

RESULTS = Path(__file__).resolve().parent / "results" / "scenes.json"

#: Scene -> (integrator, benchmark parameters, dt, steps per repetition).
SIZES = {
    "particles": ("symplectic_euler", {"count": 1 << 18}, 1e-2, 20),
    "chain": ("velocity_verlet", {"count": 2048}, 1e-3, 20),  # its reference is a dense eigh
    "heat": ("explicit_euler", {"grid": 512}, 1e-7, 20),
    "wave": ("velocity_verlet", {"grid": 512}, 1e-4, 20),
    "nbody": ("velocity_verlet", {"count": 2048}, 1e-3, 5),
    "cloth": ("symplectic_euler", {"grid": 256}, 1e-5, 20),
    "stiff_odes": ("backward_euler", {"count": 1 << 16}, 1e-3, 20),
    "ocean": ("analytic", {"grid": 256}, 1 / 60, 20),
    "throw": ("rk4", {"count": 4096}, 2e-2, 2),
}


def _step_us(
    name: str, binding: str, device: str, reps: int,
    clock: Callable[[], float] = time.perf_counter,
) -> float:  # fmt: skip
    from kdsl.scenes.measure import make_scene

    integrator, params, dt, steps = SIZES[name]
    scene = make_scene(name, "f32", integrator, device, binding=binding, **params)
    wp = scene.wp

    def run() -> None:
        for _ in range(steps):
            scene.step(dt)

    def sync() -> None:
        wp.synchronize_device(scene.device)

    return 1e6 * harness.median_seconds(run, reps, sync, clock) / steps


#: Run in a fresh process: build one scene and time its first step (the cold compile).
_COLD = """
import sys, time
from kdsl.scenes.measure import make_scene
from bench_scenes import SIZES
name, binding, device = sys.argv[1:4]
integrator, params, dt, steps = SIZES[name]
scene = make_scene(name, "f32", integrator, device, binding=binding, **params)
start = time.perf_counter()
scene.step(dt)
scene.wp.synchronize_device(scene.device)
print(time.perf_counter() - start)
"""


def cold_compile_s(name: str, binding: str, device: str) -> float:
    """Seconds of the first step of ``name`` in a fresh process with an empty cache."""
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "KDSL_CACHE": "0", "WARP_CACHE_PATH": cache}
        out = subprocess.run([sys.executable, "-c", _COLD, name, binding, device], env=env,
                             cwd=Path(__file__).resolve().parent, capture_output=True, text=True,
                             check=True)  # fmt: skip
    return float(out.stdout.strip().splitlines()[-1])


def main() -> int:
    """Measure, print the table and write the JSON."""
    parser = harness.script_parser(__doc__, RESULTS, reps=7)
    parser.add_argument("--device", default="cpu", choices=["cpu", "cuda"])
    parser.add_argument("--scenes", help="comma-separated (default: every scene)")
    parser.add_argument("--no-compile", action="store_true", help="skip the cold compiles")
    parser.add_argument("--thread-time", action="store_true",
                        help="time this thread's CPU seconds (with KDSL_CPU_THREADS=1)")  # fmt: skip
    args = parser.parse_args()
    from kdsl.backends.cpu.pool import num_threads

    names = args.scenes.split(",") if args.scenes else list(SIZES)
    rows = []
    print(f"{'scene':12s}{'integrator':18s}{'kdsl us':>11s}{'warp us':>11s}{'speedup':>9s}"
          f"{'kdsl cold s':>13s}{'warp cold s':>13s}")  # fmt: skip
    for name in names:
        clock = time.thread_time if args.thread_time else time.perf_counter
        kd = _step_us(name, "kdsl", args.device, args.reps, clock)
        wa = _step_us(name, "warp", args.device, args.reps, clock)
        row = {"scene": name, "integrator": SIZES[name][0], "params": SIZES[name][1],
               "kdsl_us": kd, "warp_us": wa, "speedup": wa / kd}  # fmt: skip
        if not args.no_compile:
            row["kdsl_cold_s"] = cold_compile_s(name, "kdsl", args.device)
            row["warp_cold_s"] = cold_compile_s(name, "warp", args.device)
        rows.append(row)
        cold = (f"{row['kdsl_cold_s']:>13.2f}{row['warp_cold_s']:>13.2f}"
                if "kdsl_cold_s" in row else "")  # fmt: skip
        print(f"{name:12s}{row['integrator']:18s}{kd:>11.1f}{wa:>11.1f}{wa / kd:>9.2f}{cold}",
              flush=True)  # fmt: skip
    result = {**harness.script_meta("bench_scenes.py"), "device": args.device,
              "kdsl_cpu_threads": num_threads(), "precision": "f32",
              "clock": "thread" if args.thread_time else "wall", "scenes": rows}  # fmt: skip
    harness.save_json(result, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
