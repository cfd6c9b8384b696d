"""How long kdsl takes to turn a kernel into optimized IR (frontend + passes).

    python benchmarks/bench_frontend.py [--reps 30] [--compile-reps 5] [--pipeline P]
                                        [--verify auto|each|end] [--json PATH]

For the seed kernels (integrate, saxpy, matmul, rosenbrock) and an all-pairs
n-body kernel, every repetition defines the kernels afresh (new ``Kernel``
objects, so no per-kernel cache survives), then times ``kernel.build_module()``
(source parsing and IR construction) and each pass of the pipeline the default
cpu backend runs, verifying as the compiler does (``kdsl.config.verify_passes``,
``--verify`` to choose). It prints a table of medians (and the minimum and the very
first, coldest run of the total) and writes everything to
benchmarks/results/frontend.json.

The large-kernel row is 4-D curl noise (``curlnoise`` on a ``vec4``), which inlines
to about 3,400 ops. Beside its row, ``--compile-reps`` fresh processes each compile
it once on the cpu backend, cold and without the disk cache (``KDSL_CACHE=0``):
``kdsl.launch`` on one thread, so frontend, passes, LLVM and loading all count (after
a one-line kernel's launch has paid the process's one-time costs).
"""

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results" / "frontend.json"
TARGET_MS = 20.0
#: The large kernel's cold compile on the cpu backend, frontend to loaded code.
LARGE_TARGET_MS = 1000.0
LARGE_NAME = "curlnoise4d"


def make_large_kernel():
    """A fresh 4-D curl noise kernel: about 3,400 ops once its calls are inlined."""
    import kdsl as wp

    @wp.kernel
    def curlnoise4d(seed: wp.array(dtype=wp.int32), x: wp.array(dtype=wp.vec4),
                    out: wp.array(dtype=wp.vec3)):  # fmt: skip
        i = wp.tid()
        out[i] = wp.curlnoise(wp.rand_init(seed[i]), x[i], wp.uint32(1), 2.0, 0.5)

    return curlnoise4d


def count_ops(kernel, pipeline: str) -> int:
    """Ops of ``kernel``'s module after ``pipeline`` (no verification)."""
    from kdsl.passes import PassManager

    module = kernel.build_module()
    PassManager(pipeline, verify_each=False).run(module)
    return sum(1 for _ in module.walk())


def _compile_child() -> None:
    """In a fresh process: compile the large kernel once, print the seconds as JSON.

    A one-line kernel is launched first, so the one-time costs of a process (importing
    the backend, starting LLVM and the thread pool) are not counted as compile time.
    """
    import numpy as np

    import kdsl as wp

    @wp.kernel
    def warm_up(a: wp.array(dtype=wp.int32)):
        a[wp.tid()] = 1

    args = [wp.array(np.zeros(1, np.int32), dtype=wp.int32),
            wp.array(np.zeros((1, 4), np.float32), dtype=wp.vec4),
            wp.zeros(1, dtype=wp.vec3)]  # fmt: skip
    start = time.perf_counter()
    wp.launch(warm_up, dim=1, inputs=args[:1], device="cpu")  # synchronous on the cpu
    warm, cpu = time.perf_counter(), time.process_time()
    wp.launch(make_large_kernel(), dim=1, inputs=args, device="cpu")
    done, cpu = time.perf_counter(), time.process_time() - cpu
    print(json.dumps({"first_launch_s": warm - start, "compile_s": done - warm,
                      "compile_cpu_s": cpu}))  # fmt: skip


def measure_cold_compiles(reps: int, verify: str | None) -> list[dict[str, float]]:
    """Seconds (wall, CPU) of ``reps`` cold compiles of the large kernel, one process each."""
    env = {**os.environ, "KDSL_CACHE": "0"}
    if verify is not None:
        env["KDSL_VERIFY_PASSES"] = verify
    command = [sys.executable, str(Path(__file__).resolve()), "--compile-child"]
    out = []
    for _ in range(reps):
        done = subprocess.run(command, env=env, capture_output=True, text=True, check=True)
        out.append(json.loads(done.stdout.strip().splitlines()[-1]))
    return out


def _pass_columns(names: list[str]) -> list[str]:
    """Unique column names for a pipeline that repeats passes: fold, fold#2, ..."""
    seen: dict[str, int] = {}
    out = []
    for n in names:
        seen[n] = seen.get(n, 0) + 1
        out.append(n if seen[n] == 1 else f"{n}#{seen[n]}")
    return out


def measure_once(kernel, pipeline: str) -> dict[str, float]:
    """Seconds per phase for one fresh kernel: frontend, each pass, verify, total."""
    from kdsl.passes import PassManager

    start = time.perf_counter()
    module = kernel.build_module()
    built = time.perf_counter()
    manager = PassManager(pipeline)  # verifies as the compiler does
    manager.run(module)
    done = time.perf_counter()
    phases = {"frontend": built - start}
    names = _pass_columns([t.name for t in manager.timings])
    for name, timing in zip(names, manager.timings):
        phases[name] = timing.seconds
    # Spent by the pass manager outside the passes: verifying the IR and the snapshot
    # it keeps before each pass for crash reproducers.
    phases["manager"] = (done - built) - sum(t.seconds for t in manager.timings)
    phases["total"] = done - start
    return phases


def _summary(runs: list[dict[str, float]]) -> dict[str, dict[str, float]]:
    out = {
        phase: {
            "median_ms": 1e3 * statistics.median(r[phase] for r in runs),
            "min_ms": 1e3 * min(r[phase] for r in runs),
        }
        for phase in runs[0]
    }
    out["total"]["first_ms"] = 1e3 * runs[0]["total"]
    return out


def run(reps: int, pipeline: str, compile_reps: int, verify: str | None) -> dict:
    """Measure every kernel ``reps`` times; returns the JSON-ready results."""
    from kdsl.passes import PassManager
    from kdsl.testing.cases.programs import make_programs

    samples: dict[str, list[dict[str, float]]] = {}
    large: list[dict[str, float]] = []
    define_s: list[float] = []
    for _ in range(reps):
        start = time.perf_counter()
        kernels = make_programs()  # fresh Kernel objects: nothing cached from last time
        define_s.append(time.perf_counter() - start)
        for name, kernel in kernels.items():
            samples.setdefault(name, []).append(measure_once(kernel, pipeline))
        large.append(measure_once(make_large_kernel(), pipeline))
    results = {name: _summary(runs) for name, runs in samples.items()}
    compiles = measure_cold_compiles(compile_reps, verify) if compile_reps else []
    kernel = make_large_kernel()
    return {
        "benchmark": "frontend+passes to optimized IR",
        "command": "python " + " ".join(sys.argv),
        "pipeline": pipeline,
        # What the pass manager does by default (kdsl.config.verify_passes resolved).
        "verify": "after each pass" if PassManager(pipeline).verify_each else "at the end",
        "repetitions": reps,
        "target_ms_per_kernel": TARGET_MS,
        "python": platform.python_version(),
        "machine": platform.machine(),
        "processor": platform.processor() or platform.machine(),
        "define_all_kernels_median_ms": 1e3 * statistics.median(define_s),
        "kernels": results,
        "large_kernel": {
            "name": LARGE_NAME,
            "ops_frontend": count_ops(kernel, ""),
            "ops_inlined": count_ops(kernel, "inline"),
            "ops_optimized": count_ops(kernel, pipeline),
            "phases": _summary(large),
            "cold_compile_processes": compile_reps,
            "cold_compile_ms": [1e3 * c["compile_s"] for c in compiles],
            "cold_compile_cpu_ms": [1e3 * c["compile_cpu_s"] for c in compiles],
            "target_ms": LARGE_TARGET_MS,
        },
    }


def format_table(data: dict) -> str:
    """The results as a fixed-width table of medians in milliseconds."""
    kernels = data["kernels"]
    large = data.get("large_kernel")
    phases = [p for p in next(iter(kernels.values())) if p != "total"]
    head = ["kernel", *phases, "total", "min", "first"]
    rows = [head]
    named = list(kernels.items()) + ([(large["name"], large["phases"])] if large else [])
    for name, ph in named:
        row = [name, *(f"{ph[p]['median_ms']:.2f}" for p in phases)]
        row += [f"{ph['total']['median_ms']:.2f}", f"{ph['total']['min_ms']:.2f}",
                f"{ph['total']['first_ms']:.2f}"]  # fmt: skip
        rows.append(row)
    widths = [max(len(r[i]) for r in rows) for i in range(len(head))]
    lines = ["  ".join(c.rjust(w) if i else c.ljust(w) for i, (c, w) in enumerate(zip(r, widths)))
             for r in rows]  # fmt: skip
    lines.insert(1, "-" * len(lines[0]))
    if large:
        lines.insert(len(kernels) + 2, "-" * len(lines[0]))
    worst = max(ph["total"]["median_ms"] for ph in kernels.values())
    verdict = "meets" if worst < data["target_ms_per_kernel"] else "MISSES"
    lines.append(
        f"\nms, median of {data['repetitions']} cold repetitions (fresh Kernel objects); "
        f"pipeline {data['pipeline']!r}, verified {data['verify']}.\n"
        f"slowest seed kernel {worst:.2f} ms: {verdict} the "
        f"{data['target_ms_per_kernel']:.0f} ms per kernel target."
    )
    if large:
        lines.append(
            f"{large['name']}: {large['ops_frontend']} ops from the frontend, "
            f"{large['ops_inlined']} inlined, {large['ops_optimized']} optimized."
        )
        wall, cpu = large["cold_compile_ms"], large["cold_compile_cpu_ms"]
        if wall:
            ms = statistics.median(wall)
            verdict = "meets" if ms < large["target_ms"] else "MISSES"
            lines.append(
                f"cold compile on cpu (kdsl.launch, fresh processes, KDSL_CACHE=0), "
                f"{len(wall)} processes: median {ms:.0f} ms (min {min(wall):.0f}; CPU time "
                f"median {statistics.median(cpu):.0f} ms): {verdict} the "
                f"{large['target_ms']:.0f} ms target."
            )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark, print the table, write the JSON file."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reps", type=int, default=30, help="repetitions (default 30)")
    parser.add_argument("--compile-reps", type=int, default=5,
                        help="fresh processes that compile the large kernel (default 5)")  # fmt: skip
    parser.add_argument("--pipeline", default=None, help="default: the cpu backend's pipeline")
    parser.add_argument("--verify", choices=("auto", "each", "end"), default=None,
                        help="kdsl.config.verify_passes (default: as configured)")  # fmt: skip
    parser.add_argument("--json", type=Path, default=RESULTS, help=f"default {RESULTS}")
    parser.add_argument("--compile-child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.compile_child:
        _compile_child()
        return 0

    import kdsl

    if args.verify is not None:
        kdsl.config.verify_passes = args.verify
    pipeline = args.pipeline
    if pipeline is None:
        from kdsl.backends.registry import get_backend

        pipeline = get_backend(kdsl.default_backend_for("cpu")).pipeline
    data = run(args.reps, pipeline, args.compile_reps, args.verify)
    print(format_table(data))
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(data, indent=2) + "\n")
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
