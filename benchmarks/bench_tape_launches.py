"""Host time per launch of a taped flight and its backward pass, kdsl beside Warp.

    python benchmarks/bench_tape_launches.py [--reps 30] [--count 1] [--json PATH]

The ``throw`` scene's kernels (RK4 flight step, loss) at ``--count`` threads (1: the
kernels cost nothing, so what is left is the host's work), a 50-step flight on the
cpu: per launch, a plain forward launch, a forward launch recorded on a ``Tape``, one
adjoint launch of ``tape.backward``, and the whole ``tape.zero()``. Times are this
thread's CPU time (``time.thread_time``), the minimum over ``--reps`` repetitions, so
other jobs on a loaded host change them less than wall time. Run it with
``KDSL_CPU_THREADS=1`` (what the README's figures use). Results go to
benchmarks/results/tape_launches.json.
"""

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results" / "tape_launches.json"
DT = 2e-2  # a 50-step flight
PHASES = ("forward", "taped_forward", "adjoint", "tape_zero_total")


def _phases(scene) -> list[float]:
    """Seconds of this thread's CPU: per forward, taped and adjoint launch, and zero()."""
    wp = scene.wp
    steps = scene.flight_steps(DT)
    h = scene.params["flight"] / steps
    xs, vs, loss = scene.flight_arrays

    def flight():
        for k in range(steps):
            wp.launch(scene.k.throw_step, scene.n,
                      [xs[k], vs[k], scene.gravity, scene.real(scene.c), scene.real(h), 3,
                       xs[k + 1], vs[k + 1]], device="cpu")  # fmt: skip

    clock = time.thread_time
    t0 = clock()
    flight()
    t1 = clock()
    tape = wp.Tape()
    with tape:
        flight()
        wp.launch(scene.k.miss_loss, scene.n, [xs[steps], scene.target_arr, loss], device="cpu")
    t2 = clock()
    tape.backward(loss=loss)
    t3 = clock()
    tape.zero()
    t4 = clock()
    return [(t1 - t0) / steps, (t2 - t1) / (steps + 1), (t3 - t2) / (steps + 1), t4 - t3]


def measure(count: int, reps: int) -> dict[str, dict[str, float]]:
    """Per framework and phase: the minimum over ``reps`` (microseconds)."""
    from kdsl.scenes.measure import make_scene

    scenes = {b: make_scene("throw", "f32", "rk4", "cpu", binding=b, count=count)
              for b in ("kdsl", "warp")}  # fmt: skip
    for s in scenes.values():
        wp, n = s.wp, s.n
        arrays = [[wp.zeros(n, dtype=s.k.vec3, device="cpu", requires_grad=True)
                   for _ in range(s.flight_steps(DT) + 1)] for _ in range(2)]  # fmt: skip
        s.flight_arrays = (*arrays, wp.zeros(1, dtype=s.real, device="cpu", requires_grad=True))
        for _ in range(2):  # compile, then prepare what is reused
            _phases(s)
    samples: dict[str, list[list[float]]] = {b: [] for b in scenes}
    for _ in range(reps):
        for b, s in scenes.items():  # interleaved: drift hits both alike
            samples[b].append(_phases(s))
    return {b: {p: 1e6 * min(col) for p, col in zip(PHASES, zip(*rows))}
            for b, rows in samples.items()}  # fmt: skip


def main() -> int:
    """Measure, print the table and write the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reps", type=int, default=30)
    parser.add_argument("--count", type=int, default=1)
    parser.add_argument("--json", type=Path, default=RESULTS)
    args = parser.parse_args()
    from kdsl.backends.cpu.pool import num_threads

    result = measure(args.count, args.reps)
    print(f"{'us (thread CPU)':18s}" + "".join(f"{p:>17s}" for p in PHASES))
    for b, row in result.items():
        print(f"{b:18s}" + "".join(f"{row[p]:>17.1f}" for p in PHASES))
    out = {
        "command": " ".join(["python", "benchmarks/bench_tape_launches.py", *sys.argv[1:]]),
        "python": sys.version.split()[0],
        "machine": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
        "load_average": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
        "kdsl_cpu_threads": num_threads(),
        "count": args.count,
        "microseconds": result,
    }
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(out, indent=2))
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
