"""float32 sin/cos throughput on the cpu, per element, kdsl beside Warp.

    python benchmarks/bench_trig_cpu.py [--reps 15] [--n 1048576] [--threads 1]
                                        [--frameworks kdsl,warp] [--json PATH]

Each kernel runs over ``n`` float32 values in [-100, 100]; the time per element is the
minimum over ``--reps`` launches (after one untimed launch: the compile). kdsl runs on
``--threads`` threads (default 1: Warp's cpu kernels run on one, and per-core speed is
what the math lowering decides). With one thread each, times are the calling thread's
CPU time (``time.thread_time``: both run a one-thread launch on the calling thread),
which other jobs on a shared host disturb less than the wall clock; with more, wall
time. The last row is the ``ocean`` scene's step at the ``bench_scenes`` size (256^2
points, 8 waves), in microseconds. Kernels: ``sin`` (``y = sin x``), ``sincos``
(``y = sin x + cos x``), ``waves`` (eight ``sin``/``cos`` pairs of ``k_w x + p_w`` summed
per element, the ocean scene's inner loop) and ``sin_f64`` (float64, for scale).
Results go to benchmarks/results/trig_cpu.json (``times``: ns per element, ``ocean_us``).
"""

import importlib
import os
import sys
import time
from pathlib import Path
from types import ModuleType, SimpleNamespace

import numpy as np
from suite import harness

RESULTS = Path(__file__).resolve().parent / "results" / "trig_cpu.json"
NAMES = ("sin", "sincos", "waves", "sin_f64")


def make_kernels(wp: ModuleType) -> SimpleNamespace:
    """The benchmark's kernels, written once against kdsl's or Warp's ``wp``."""

    @wp.kernel(module="unique")
    def sin(x: wp.array(dtype=float), k: wp.array(dtype=float), y: wp.array(dtype=float)):
        i = wp.tid()
        y[i] = wp.sin(x[i])

    @wp.kernel(module="unique")
    def sincos(x: wp.array(dtype=float), k: wp.array(dtype=float), y: wp.array(dtype=float)):
        i = wp.tid()
        y[i] = wp.sin(x[i]) + wp.cos(x[i])

    @wp.kernel(module="unique")
    def waves(x: wp.array(dtype=float), k: wp.array(dtype=float), y: wp.array(dtype=float)):
        i = wp.tid()
        s = wp.float32(0.0)
        c = wp.float32(0.0)
        for w in range(k.shape[0]):
            theta = k[w] * x[i] + float(w)
            s = s + wp.sin(theta)
            c = c + wp.cos(theta)
        y[i] = s * c

    @wp.kernel(module="unique")
    def sin_f64(
        x: wp.array(dtype=wp.float64), k: wp.array(dtype=float), y: wp.array(dtype=wp.float64)
    ):
        i = wp.tid()
        y[i] = wp.sin(x[i])

    return SimpleNamespace(sin=sin, sincos=sincos, waves=waves, sin_f64=sin_f64)


def ns_per_element(wp: ModuleType, kernel, n: int, reps: int, f64: bool, per: int, clock) -> float:
    """Minimum ns per element (``per`` sin/cos evaluations count as one element)."""
    rng = np.random.default_rng(0)
    dtype, npt = (wp.float64, np.float64) if f64 else (wp.float32, np.float32)
    x = wp.array(rng.uniform(-100.0, 100.0, n).astype(npt), dtype=dtype, device="cpu")
    k = wp.array(rng.uniform(0.1, 3.0, 8).astype(np.float32), dtype=wp.float32, device="cpu")
    y = wp.zeros(n, dtype=dtype, device="cpu")
    wp.launch(kernel, n, [x, k, y], device="cpu")
    wp.synchronize_device("cpu")
    best = float("inf")
    for _ in range(reps):
        t = clock()
        wp.launch(kernel, n, [x, k, y], device="cpu")
        wp.synchronize_device("cpu")
        best = min(best, clock() - t)
    return 1e9 * best / (n * per)


def ocean_step_us(binding: str, reps: int, clock) -> float:
    """Minimum microseconds per ``ocean`` step (``bench_scenes.SIZES``), 5 steps a repetition."""
    from bench_scenes import SIZES

    from kdsl.scenes.measure import make_scene

    integrator, params, dt, _ = SIZES["ocean"]
    scene = make_scene("ocean", "f32", integrator, "cpu", binding=binding, **params)
    scene.step(dt)
    best = float("inf")
    for _ in range(reps):
        t = clock()
        for _ in range(5):
            scene.step(dt)
        scene.wp.synchronize_device("cpu")
        best = min(best, (clock() - t) / 5)
    return 1e6 * best


def main() -> int:
    """Measure, print the table and write the JSON."""
    parser = harness.script_parser(__doc__, RESULTS, reps=15)
    parser.add_argument("--n", type=int, default=1 << 20)
    parser.add_argument("--threads", type=int, default=1, help="kdsl's cpu threads")
    parser.add_argument("--frameworks", default="kdsl,warp")
    args = parser.parse_args()
    os.environ["KDSL_CPU_THREADS"] = str(args.threads)  # read when kdsl's pool starts
    clock = time.thread_time if args.threads == 1 else time.perf_counter
    frameworks = args.frameworks.split(",")
    found = {}
    for fw in frameworks:
        wp = importlib.import_module("kdsl" if fw == "kdsl" else "warp")
        if fw == "warp":
            wp.config.quiet = True
            wp.init()
        ks = make_kernels(wp)
        # waves: eight sin/cos pairs per element; report per pair.
        found[fw] = {name: ns_per_element(wp, getattr(ks, name), args.n, args.reps,
                                          name == "sin_f64", 8 if name == "waves" else 1, clock)
                     for name in NAMES}  # fmt: skip
        found[fw]["ocean_us"] = ocean_step_us(fw, args.reps, clock)
    print(f"{'kernel':10s}" + "".join(f"{fw + ' ns':>12s}" for fw in frameworks)
          + (f"{'warp/kdsl':>11s}" if {"kdsl", "warp"} <= set(frameworks) else ""))  # fmt: skip
    for name in (*NAMES, "ocean_us"):
        row = "".join(f"{found[fw][name]:>12.2f}" for fw in frameworks)
        if {"kdsl", "warp"} <= set(frameworks):
            row += f"{found['warp'][name] / found['kdsl'][name]:>11.2f}"
        print(f"{name:10s}{row}")
    result = {**harness.script_meta("bench_trig_cpu.py"), "n": args.n, "reps": args.reps,
              "kdsl_cpu_threads": args.threads,
              "clock": "thread_time" if args.threads == 1 else "perf_counter",
              "times": found}  # fmt: skip
    harness.save_json(result, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
