"""A cpu launch on the thread pool against inline, after the host paused for a while.

    python benchmarks/bench_pool_wake.py [--reps 8] [--gaps 0,25,50,100,200,400,1000]
                                         [--json PATH]

The backward pass of the ``throw`` scene (4,096 throws, RK4, a 50-step flight) is
run once, so its adjoint launches are prepared (``LaunchReuse``); then each prepared
adjoint launch is timed alone, inline and on the pool (``pool.adaptive = False``),
after the launching thread busy-waits ``gap`` microseconds in Python (the host work
a launch path does between two kernels). A pool worker polls for ``WORKER_SPIN``
yields after its share, then sleeps on a futex; a launch that finds it asleep pays
for its wake-up (on a VM, waking an idle vCPU). The table shows how a launch's pool
cost beyond inline grows with the gap. Results go to benchmarks/results/pool_wake.json.
"""

import os
import statistics
import sys
import time
from pathlib import Path

from suite.harness import save_json, script_meta, script_parser

RESULTS = Path(__file__).resolve().parent / "results" / "pool_wake.json"


def _prepared_adjoints() -> list:
    """The throw scene's prepared adjoint launches, in backward order."""
    from kdsl.runtime.adjoint import adjoint_kernel
    from kdsl.runtime.launch import launch_plan
    from kdsl.scenes.measure import make_scene

    scene = make_scene("throw", "f32", "rk4", "cpu", binding="kdsl", count=4096)
    for _ in range(4):  # the second pass prepares, later ones reuse
        scene.step(2e-2)
    entries = launch_plan(adjoint_kernel(scene.k.throw_step), "cpu", None).reuse.entries
    return [run for run, _ in entries.values()][::-1]


def _busy_wait(us: float) -> None:
    end = time.perf_counter() + us * 1e-6
    while time.perf_counter() < end:
        pass


def measure(gaps: list[int], reps: int) -> list[dict]:
    """Per gap: median and 10th percentile of one launch, inline and on the pool (us)."""
    from kdsl.backends.cpu import pool

    runs = _prepared_adjoints()
    samples: dict[tuple[int, str], list[float]] = {}
    old = pool.adaptive, pool.min_parallel
    pool.adaptive = False
    try:
        for _ in range(reps):
            for gap in gaps:
                for mode, threshold in (("inline", 1 << 30), ("pool", 2)):
                    pool.min_parallel = threshold
                    for run in runs:
                        _busy_wait(gap)
                        t0 = time.perf_counter()
                        run()
                        samples.setdefault((gap, mode), []).append(time.perf_counter() - t0)
    finally:
        pool.adaptive, pool.min_parallel = old
    rows = []
    for gap in gaps:
        row: dict = {"gap_us": gap}
        for mode in ("inline", "pool"):
            s = sorted(samples[(gap, mode)])
            row[f"{mode}_median_us"] = 1e6 * statistics.median(s)
            row[f"{mode}_p10_us"] = 1e6 * s[len(s) // 10]
        rows.append(row)
    return rows


def main() -> int:
    """Measure, print the table and write the JSON."""
    parser = script_parser(__doc__, RESULTS, reps=8)
    parser.add_argument("--gaps", default="0,25,50,100,200,400,1000")
    args = parser.parse_args()
    from kdsl.backends.cpu.pool import num_threads

    if num_threads() < 2:
        print("one cpu thread (KDSL_CPU_THREADS=1?): there is no pool to compare")
        return 2
    rows = measure([int(g) for g in args.gaps.split(",")], args.reps)
    print(f"{'gap us':>8s}{'inline med':>12s}{'inline p10':>12s}{'pool med':>10s}"
          f"{'pool p10':>10s}")  # fmt: skip
    for r in rows:
        print(f"{r['gap_us']:>8d}{r['inline_median_us']:>12.1f}{r['inline_p10_us']:>12.1f}"
              f"{r['pool_median_us']:>10.1f}{r['pool_p10_us']:>10.1f}")  # fmt: skip
    result = {
        **script_meta("bench_pool_wake.py"),
        "load_average": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
        "kdsl_cpu_threads": num_threads(),
        "rows": rows,
    }
    save_json(result, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
