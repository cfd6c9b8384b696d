"""Where the cpu backend's thread pool starts to pay: the inline-launch threshold.

    python benchmarks/bench_launch.py [--reps 30] [--max-log2 20] [--json PATH]

A launch smaller than ``kdsl.backends.cpu.pool.min_parallel`` threads runs on the
calling thread; a larger one is split over the pool. This script measures, for a
cheap kernel (saxpy: a few nanoseconds per thread) and a heavy one (a 32-step loop
of transcendental math per thread), the median time of a launch of 2^k threads
run inline and run on the pool, and reports the smallest size at which the pool
wins for each. The default ``min_parallel`` is the cheap kernel's crossover: a
kernel that does more per thread would gain from the pool a little earlier, but
never loses much by running inline below that size, while a cheap kernel sent to
the pool too early pays the pool's dispatch cost many times over.

It also prints the host overhead of a dim=1 launch with two array arguments:
``kdsl.launch`` and a prepared launch (``record_cmd=True`` then ``Launch.launch``).
Results go to benchmarks/results/launch.json.
"""

import statistics
import sys
import time
from pathlib import Path

import numpy as np
from suite.harness import median_seconds, save_json, script_meta, script_parser

import kdsl as wp
from kdsl.backends.cpu import num_threads, pool

RESULTS = Path(__file__).resolve().parent / "results" / "launch.json"


@wp.kernel
def saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
    i = wp.tid()
    y[i] = a * x[i] + y[i]


@wp.kernel
def heavy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
    i = wp.tid()
    v = x[i]
    for _ in range(32):
        v = wp.sin(v * a) + wp.cos(v)
    y[i] = v


@wp.kernel
def copy1(a: wp.array(dtype=float), b: wp.array(dtype=float)):
    i = wp.tid()
    b[i] = a[i]


def crossover(kernel, max_log2: int, reps: int) -> tuple[list[dict], int | None]:
    """Inline and pooled launch times per size, and the first size where the pool wins."""
    rows, first = [], None
    saved = pool.min_parallel, pool.adaptive
    pool.adaptive = False  # min_parallel alone decides, so each column is the path it names
    try:
        for k in range(4, max_log2 + 1):
            n = 1 << k
            x = wp.array(np.linspace(0.0, 1.0, n, dtype=np.float32), dtype=float)
            y = wp.zeros(n, dtype=float)

            def run(x=x, y=y, n=n):
                wp.launch(kernel, n, [x, y, 0.5])

            # cpu launches return finished: nothing to synchronize.
            pool.min_parallel = 1 << 62
            inline = median_seconds(run, reps, sync=lambda: None)
            pool.min_parallel = 1
            pooled = median_seconds(run, reps, sync=lambda: None)
            rows.append({"threads": n, "inline_us": inline * 1e6, "pool_us": pooled * 1e6})
            # The first of two consecutive sizes where the pool wins: one noisy win is not enough.
            if first is None and pooled < inline and len(rows) > 1:
                prev = rows[-2]
                if prev["pool_us"] < prev["inline_us"]:
                    first = prev["threads"]
    finally:
        pool.min_parallel, pool.adaptive = saved
    return rows, first


def launch_overhead(reps: int) -> dict[str, float]:
    """Microseconds per dim=1 launch with two array arguments: plain and prepared."""
    a, b = wp.zeros(1, dtype=float), wp.zeros(1, dtype=float)
    wp.launch(copy1, 1, [a, b])
    n = 20000
    plain, prepared = [], []
    cmd = wp.launch(copy1, 1, [a, b], record_cmd=True)
    for _ in range(reps):
        t0 = time.perf_counter()
        for _ in range(n):
            wp.launch(copy1, 1, [a, b])
        plain.append((time.perf_counter() - t0) / n * 1e6)
        t0 = time.perf_counter()
        for _ in range(n):
            cmd.launch()
        prepared.append((time.perf_counter() - t0) / n * 1e6)
    return {"launch_us": statistics.median(plain), "prepared_us": statistics.median(prepared)}


def main() -> int:
    """Measure, print the tables and write the JSON."""
    parser = script_parser(__doc__, RESULTS, reps=30)
    parser.add_argument("--max-log2", type=int, default=20)
    args = parser.parse_args()

    over = launch_overhead(max(3, args.reps // 6))
    print(f"threads: {num_threads()}   min_parallel now: {pool.min_parallel}")
    print(f"dim=1 launch, two arrays: {over['launch_us']:.2f} us; "
          f"prepared: {over['prepared_us']:.2f} us\n")  # fmt: skip
    result = {**script_meta("bench_launch.py"), "threads": num_threads(), "overhead": over,
              "kernels": {}}  # fmt: skip
    for kernel in (saxpy, heavy):
        rows, first = crossover(kernel, args.max_log2, args.reps)
        result["kernels"][kernel.key] = {"rows": rows, "crossover": first}
        wins = first if first else f"never (up to 2^{args.max_log2})"
        print(f"{kernel.key}: pool wins from {wins}")
        print(f"{'threads':>9} {'inline us':>10} {'pool us':>10} {'speedup':>8}")
        for r in rows:
            print(f"{r['threads']:>9} {r['inline_us']:>10.1f} {r['pool_us']:>10.1f} "
                  f"{r['inline_us'] / r['pool_us']:>8.2f}")  # fmt: skip
        print()
    save_json(result, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
