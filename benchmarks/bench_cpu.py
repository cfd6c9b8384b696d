"""kdsl against Warp (CPU), Taichi (ti.cpu) and Numba (parallel=True), side by side.

    python benchmarks/bench_cpu.py [--quick] [--only W1,W2] [--frameworks kdsl,warp]
                                   [--reps N] [--json PATH]

Every framework runs every workload on the same float32 data; each result is checked
against a float64 NumPy reference before it is timed (a wrong result is flagged in
its cell). Frameworks that are not installed (the ``bench`` extra) are reported and
skipped, and a framework that fails shows ``error: ...`` in its cell while the rest
goes on. The table gives medians; the last columns give kdsl's ratio to the fastest
peer (>1: kdsl is faster) and whether the issue's target is met. Everything,
samples included, goes to benchmarks/results/cpu-<timestamp>.json. The exit status
is 1 when a kdsl result failed its check (wrong or an error), so a run that checked
nothing of kdsl never reads as a success.

Workloads: saxpy, particles, nbody, nbody_fast, jacobi, cloth, launch,
launch_prepared (``suite.workloads``), plus triad (Numba's STREAM triad bandwidth,
which saxpy's is held to), scaling (kdsl's n-body speedup from 1 to 2 threads), graph
(kdsl's 100-kernel step replayed as one graph against 100 launches: the speedup), leaks
(kdsl's resident memory over 10^5 launches, 10^4 captures and 10^4 allocations:
``suite.leaks``), and cold_compile, compile and warm_start, measured in fresh processes with a fresh (then
reused) kernel cache directory.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from suite import harness
from suite.harness import Cell, Stats
from suite.workloads import (
    PROCESS_WORKLOADS,
    START_BODIES,
    WORKLOADS,
)

FRAMEWORKS = ("kdsl", "warp", "taichi", "numba")
PEERS = FRAMEWORKS[1:]
#: Step workloads in run order: Taichi's fast-math n-body re-initializes Taichi, so last.
RUN_ORDER = ("saxpy", "particles", "nbody", "jacobi", "cloth", "launch", "launch_prepared",
             "nbody_fast")  # fmt: skip
ALL = (*WORKLOADS, "triad", "scaling", "graph", "leaks", *PROCESS_WORKLOADS)
RESULTS = Path(__file__).resolve().parent / "results"
PROCESS_REPS = 3


def load_frameworks(names: list[str]) -> dict[str, Any]:
    """name -> impl module, or the status string of a framework that cannot be used."""
    return harness.load_impls(names)


def run_step_workload(wname: str, mod: Any, quick: bool, reps: int | None) -> Cell:
    """Prepare, verify (the first step also compiles), then time one framework."""
    return harness.run_step(WORKLOADS[wname], mod, "cpu", quick, reps)


def run_triad(mod: Any, quick: bool, reps: int | None) -> Cell:
    """Numba's STREAM triad bandwidth, in GB/s (stored as the median)."""
    n = WORKLOADS["saxpy"].quick_size if quick else WORKLOADS["saxpy"].size
    runner, nbytes = mod.triad(n)
    stats = harness.measure(runner.step, reps or 20, warmup=2)
    return Cell(Stats(nbytes / stats.median / 1e9, nbytes / stats.min / 1e9, stats.spread),
                extra={"seconds": stats.median})  # fmt: skip


def run_scaling(mod: Any, quick: bool, reps: int | None) -> Cell:
    """kdsl's n-body at 1 and 2 threads; the median is the speedup."""
    w = WORKLOADS["nbody"]
    ins = w.make_inputs(1024 if quick else 8192, np.random.default_rng(7))
    times = {}
    try:
        for threads in (1, 2):
            mod.set_threads(threads)
            runner = mod.nbody(harness.copy_inputs(ins))
            runner.step()
            times[threads] = harness.measure(runner.step, reps or 3).median
    finally:
        mod.set_threads(None)
    speedup = times[1] / times[2]
    return Cell(Stats(speedup, speedup, 0.0), extra={"seconds": times})


def run_process(mod: Any, quick: bool) -> dict[str, Cell]:
    """Cold start, compile and warm start of a small n-body, each in a fresh process."""
    if not hasattr(mod, "start_script"):
        return {k: Cell(status="n/a") for k in PROCESS_WORKLOADS}
    cold, compile_, warm = [], [], []
    reps = 1 if quick else PROCESS_REPS
    try:
        for _ in range(reps):
            with (
                tempfile.TemporaryDirectory(prefix="bench-cache-") as cache,
                tempfile.TemporaryDirectory(prefix="bench-script-") as workdir,
            ):
                src, env = mod.start_script(cache, START_BODIES)
                first = harness.run_script(src, env, workdir=workdir)
                cold.append(first["first_epoch"] - first["spawn_epoch"])
                compile_.append(first["compile_s"])
                # Same script path: a kernel cache keyed by source locations must hit.
                again = harness.run_script(src, env, workdir=workdir)
                warm.append(again["after_import_s"])
    except Exception as e:
        return {k: Cell(status=harness.short_error(e)) for k in PROCESS_WORKLOADS}
    return {"cold_compile": Cell(Stats.of(cold)), "compile": Cell(Stats.of(compile_)),
            "warm_start": Cell(Stats.of(warm))}  # fmt: skip


# -- the table ------------------------------------------------------------------------
def _median(cell: Cell | None) -> float | None:
    return (
        cell.stats.median
        if cell is not None and cell.stats is not None and cell.status == "ok"
        else None
    )


def _vs_peers(row: dict[str, Cell]) -> tuple[str, str, bool | None]:
    """(best peer, kdsl speedup over it, target met) for a lower-is-better row."""
    peers = {f: _median(row.get(f)) for f in PEERS}
    peers = {f: t for f, t in peers.items() if t is not None}
    mine = _median(row.get("kdsl"))
    if not peers or mine is None:
        return "-", "-", None
    best = min(peers, key=peers.get)
    ratio = peers[best] / mine
    return best, f"{ratio:.2f}x", ratio >= 1.0


def target_rows(cells: dict[str, dict[str, Cell]], saxpy_n: int) -> list[list[str]]:
    """The table's rows: one per workload measured."""
    rows = []
    units = {"launch": "us", "launch_prepared": "us", "cold_compile": "s", "compile": "s",
             "warm_start": "ms"}  # fmt: skip
    for wname in ALL:
        row = cells.get(wname)
        if row is None:
            continue
        title = WORKLOADS[wname].title if wname in WORKLOADS else wname.replace("_", " ")
        unit = units.get(wname, "ms")
        best, ratio, met = _vs_peers(row)
        mine = _median(row.get("kdsl"))
        target = "-" if met is None else ("yes" if met else "no")
        if wname == "triad":
            title, unit = "triad GB/s (numba)", "GB/s"
            best, ratio, target = "-", "-", "-"
        elif wname == "scaling":
            title, unit = "n-body 1->2 threads", "x"
            best, ratio = "-", "-"
            target = "-" if mine is None else ("yes" if mine >= 1.8 else "no") + " (>=1.8x)"
        elif wname == "graph":
            from suite.graph_step import graph_title

            title, unit = graph_title(row.get("kdsl")), "x"
            best, ratio = "-", "-"
        elif wname == "launch_prepared" and mine is not None:
            target = ("yes" if mine < 2e-6 else "no") + " (<2us)"
        elif wname in ("cold_compile", "compile"):
            warp = _median(row.get("warp"))
            if mine is not None and warp is not None:
                target = ("yes" if mine <= warp / 5 else "no") + " (<=warp/5)"
        elif wname == "warm_start" and mine is not None:
            target = ("yes" if mine < 0.05 else "no") + " (<50ms)"
        title = f"{title} [{unit}]"
        rows.append([title, *[harness.format_cell(row.get(f), unit) for f in FRAMEWORKS],
                     best, ratio, target])  # fmt: skip
    if "saxpy" in cells and "triad" in cells:
        rows.append(bandwidth_row(cells, saxpy_n))
    from suite.leaks import COUNTS, leak_row

    for name in COUNTS:
        if f"leak_{name}" in cells:
            title, text, target, _ = leak_row(name, cells[f"leak_{name}"].get("kdsl"))
            rows.append([title, text, "-", "-", "-", "-", "-", target])
    return rows


def bandwidth_row(cells: dict[str, dict[str, Cell]], n: int) -> list[str]:
    """saxpy's bandwidth (12 bytes per element) per framework, against Numba's triad."""
    triad = _median(cells["triad"].get("numba"))
    out, mine = [], None
    for f in FRAMEWORKS:
        t = _median(cells["saxpy"].get(f))
        gbs = None if t is None else 12 * n / t / 1e9
        if f == "kdsl":
            mine = gbs
        out.append("-" if gbs is None else f"{gbs:.3g}")
    frac = "-" if mine is None or triad is None else f"{mine / triad:.2f}"
    target = "-" if frac == "-" else ("yes" if mine >= 0.8 * triad else "no") + " (>=0.8 triad)"
    return ["saxpy GB/s", *out, "triad", frac, target]


def main() -> int:
    """Parse the arguments, run the selected workloads, print the table, write JSON."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="small sizes, one process rep")
    p.add_argument("--only", default=",".join(ALL), help=f"comma list of {', '.join(ALL)}")
    p.add_argument("--frameworks", default=",".join(FRAMEWORKS))
    p.add_argument(
        "--reps", type=int, default=None, help="timed repetitions (default per workload)"
    )
    p.add_argument("--json", type=Path, default=None)
    args = p.parse_args()

    only = [w.strip() for w in args.only.split(",") if w.strip()]
    unknown = [w for w in only if w not in ALL]
    chosen = [f.strip() for f in args.frameworks.split(",") if f.strip()]
    bad = [f for f in chosen if f not in FRAMEWORKS]
    if unknown or bad:
        p.error(f"unknown workloads {unknown} or frameworks {bad}")
    mods = load_frameworks(chosen)
    for f, m in mods.items():
        print(f"{f}: {m if isinstance(m, str) else m.version()}", flush=True)

    cells: dict[str, dict[str, Cell]] = {}
    start = time.perf_counter()
    for wname in (w for w in RUN_ORDER if w in only):
        row = cells.setdefault(wname, {})
        for f in chosen:
            m = mods[f]
            row[f] = (
                Cell(status=m)
                if isinstance(m, str)
                else run_step_workload(wname, m, args.quick, args.reps)
            )
            print(f"  {wname:16s} {f:7s} {harness.format_cell(row[f], 'ms')}", flush=True)
    saxpy_n = WORKLOADS["saxpy"].quick_size if args.quick else WORKLOADS["saxpy"].size
    if "triad" in only and not isinstance(mods.get("numba", "x"), str):
        try:
            cells["triad"] = {"numba": run_triad(mods["numba"], args.quick, args.reps)}
        except Exception as e:
            cells["triad"] = {"numba": Cell(status=harness.short_error(e))}
    if "scaling" in only and not isinstance(mods.get("kdsl", "x"), str):
        try:
            cells["scaling"] = {"kdsl": run_scaling(mods["kdsl"], args.quick, args.reps)}
        except Exception as e:
            cells["scaling"] = {"kdsl": Cell(status=harness.short_error(e))}
    if "graph" in only and not isinstance(mods.get("kdsl", "x"), str):
        from suite.graph_step import run_graph

        cells["graph"] = {"kdsl": run_graph("cpu", args.quick, args.reps)}
    if "leaks" in only and not isinstance(mods.get("kdsl", "x"), str):
        from suite.leaks import run_leaks

        for k, c in run_leaks("cpu", args.quick).items():
            cells[k] = {"kdsl": c}
    if any(w in only for w in PROCESS_WORKLOADS):
        for f in chosen:
            m = mods[f]
            res = ({k: Cell(status=m) for k in PROCESS_WORKLOADS} if isinstance(m, str)
                   else run_process(m, args.quick))  # fmt: skip
            for k, c in res.items():
                if k in only:
                    cells.setdefault(k, {})[f] = c
            print(f"  {'process':16s} {f:7s} done", flush=True)
    elapsed = time.perf_counter() - start

    print()
    headers = ["workload [unit]", *FRAMEWORKS, "best peer", "kdsl vs best", "target met"]
    harness.print_table(headers, target_rows(cells, saxpy_n))
    if "leaks" in only:
        from suite.leaks import print_details

        print_details(cells)
    print(
        f"\n{'quick' if args.quick else 'full'} run in {elapsed:.0f} s; medians; "
        "kdsl vs best > 1 means kdsl is faster"
    )

    path = args.json or RESULTS / f"cpu-{time.strftime('%Y%m%d-%H%M%S')}.json"
    meta = {
        "command": " ".join(sys.argv),
        "quick": args.quick,
        "elapsed_s": elapsed,
        "versions": {f: (m if isinstance(m, str) else m.version()) for f, m in mods.items()},
    }
    harness.save_json(harness.to_json(cells, meta), path)
    return harness.exit_status(cells, "bench_cpu")


if __name__ == "__main__":
    raise SystemExit(main())
