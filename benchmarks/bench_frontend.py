"""How long kdsl takes to turn a kernel into optimized IR (frontend + passes).

    python benchmarks/bench_frontend.py [--reps 30] [--pipeline P] [--json PATH]

For the seed kernels (integrate, saxpy, matmul, rosenbrock) and an all-pairs
n-body kernel, every repetition defines the kernels afresh (new ``Kernel``
objects, so no per-kernel cache survives), then times ``kernel.build_module()``
(source parsing and IR construction) and each pass of the pipeline the default
cpu backend runs, with verification after each pass as the compiler does. It
prints a table of medians (and the minimum and the very first, coldest run of
the total) and writes everything to benchmarks/results/frontend.json.
"""

import argparse
import json
import platform
import statistics
import sys
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results" / "frontend.json"
TARGET_MS = 20.0


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
    manager = PassManager(pipeline, verify_each=True)
    manager.run(module)
    done = time.perf_counter()
    phases = {"frontend": built - start}
    names = _pass_columns([t.name for t in manager.timings])
    for name, timing in zip(names, manager.timings):
        phases[name] = timing.seconds
    # Spent by the pass manager outside the passes: verifying after each pass and the
    # IR snapshot it keeps for crash reproducers.
    phases["manager"] = (done - built) - sum(t.seconds for t in manager.timings)
    phases["total"] = done - start
    return phases


def run(reps: int, pipeline: str) -> dict:
    """Measure every kernel ``reps`` times; returns the JSON-ready results."""
    from kdsl.testing.cases.programs import make_programs

    samples: dict[str, list[dict[str, float]]] = {}
    define_s: list[float] = []
    for _ in range(reps):
        start = time.perf_counter()
        kernels = make_programs()  # fresh Kernel objects: nothing cached from last time
        define_s.append(time.perf_counter() - start)
        for name, kernel in kernels.items():
            samples.setdefault(name, []).append(measure_once(kernel, pipeline))
    results = {}
    for name, runs in samples.items():
        phases = list(runs[0])
        results[name] = {
            phase: {
                "median_ms": 1e3 * statistics.median(r[phase] for r in runs),
                "min_ms": 1e3 * min(r[phase] for r in runs),
            }
            for phase in phases
        }
        results[name]["total"]["first_ms"] = 1e3 * runs[0]["total"]
    return {
        "benchmark": "frontend+passes to optimized IR",
        "command": "python " + " ".join(sys.argv),
        "pipeline": pipeline,
        "repetitions": reps,
        "target_ms_per_kernel": TARGET_MS,
        "python": platform.python_version(),
        "machine": platform.machine(),
        "processor": platform.processor() or platform.machine(),
        "define_all_kernels_median_ms": 1e3 * statistics.median(define_s),
        "kernels": results,
    }


def format_table(data: dict) -> str:
    """The results as a fixed-width table of medians in milliseconds."""
    kernels = data["kernels"]
    phases = [p for p in next(iter(kernels.values())) if p != "total"]
    head = ["kernel", *phases, "total", "min", "first"]
    rows = [head]
    for name, ph in kernels.items():
        row = [name, *(f"{ph[p]['median_ms']:.2f}" for p in phases)]
        row += [f"{ph['total']['median_ms']:.2f}", f"{ph['total']['min_ms']:.2f}",
                f"{ph['total']['first_ms']:.2f}"]  # fmt: skip
        rows.append(row)
    widths = [max(len(r[i]) for r in rows) for i in range(len(head))]
    lines = ["  ".join(c.rjust(w) if i else c.ljust(w) for i, (c, w) in enumerate(zip(r, widths)))
             for r in rows]  # fmt: skip
    lines.insert(1, "-" * len(lines[0]))
    worst = max(ph["total"]["median_ms"] for ph in kernels.values())
    verdict = "meets" if worst < data["target_ms_per_kernel"] else "MISSES"
    lines.append(
        f"\nms, median of {data['repetitions']} cold repetitions (fresh Kernel objects); "
        f"pipeline {data['pipeline']!r}.\nslowest kernel {worst:.2f} ms: {verdict} the "
        f"{data['target_ms_per_kernel']:.0f} ms per kernel target."
    )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark, print the table, write the JSON file."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reps", type=int, default=30, help="repetitions (default 30)")
    parser.add_argument("--pipeline", default=None, help="default: the cpu backend's pipeline")
    parser.add_argument("--json", type=Path, default=RESULTS, help=f"default {RESULTS}")
    args = parser.parse_args(argv)

    import kdsl

    pipeline = args.pipeline
    if pipeline is None:
        from kdsl.backends.registry import get_backend

        pipeline = get_backend(kdsl.default_backend_for("cpu")).pipeline
    data = run(args.reps, pipeline)
    print(format_table(data))
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(data, indent=2) + "\n")
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
