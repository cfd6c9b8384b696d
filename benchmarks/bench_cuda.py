"""kdsl against Warp, Taichi (ti.cuda) and hand-written CUDA C (CuPy) on a GPU, side by side.

    python benchmarks/bench_cuda.py [--quick] [--only W1,W2] [--frameworks kdsl,warp]
                                    [--reps N] [--json PATH] [--device cuda:0]
                                    [--skip-compile]

The same workloads, float32 data and float64 NumPy references as bench_cpu
(``suite.workloads``), plus saxpy at 2^26 and a device-to-device copy of 2^26
floats (CuPy's ``cudaMemcpyAsync``), the bandwidth saxpy is held to. Every
framework's first result is checked against the reference before it is timed.

Timing: each framework enqueues on its own stream (kdsl: ``kdsl.get_stream``;
Warp: its current stream; Taichi and CuPy: their defaults). A sample is a batch of
back-to-back launches between two synchronizations of that framework (so all of
its work is inside the timed region), divided by the batch; the table gives the
median of the samples. Launch overhead is host time per launch of a dim=1 kernel
with two array arguments over 2000 launches and one final sync, plain and prepared
(``record_cmd=True``); CuPy's ``RawKernel`` call is its plain launch. Compile rows
run an n-body module in fresh processes with an empty kernel cache (cold), then
again with the same cache (warm); "compile" is first launch to first result,
"start" is process start to first result.

Frameworks that are not installed are reported and skipped; a failing cell shows
``error [k]`` with the message in a note under the table. The graph row (kdsl only)
replays a 100-kernel step captured with ``kdsl.ScopedCapture`` against the same 100
launches; its cell is the speedup (target >= 5x). The leak rows (``suite.leaks``)
give the growth of resident memory over 10^5 launches, 10^4 captures with replays
and 10^4 allocate/free cycles, with CuPy's pool before and after (target: flat
within 1%). Without a CUDA device the
script says so and exits 1: nothing was measured (``--device cpu`` runs its logic
on the CPU, CuPy skipped: a check of the script, not a benchmark). It also exits 1
when a kdsl result failed its check against the reference. Everything, samples included,
goes to benchmarks/results/cuda-<timestamp>.json.
"""

from __future__ import annotations

import argparse
import gc
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from suite import harness
from suite.harness import Cell, Stats
from suite.workloads import CUDA_WORKLOADS, START_BODIES, WORKLOADS

FRAMEWORKS = ("kdsl", "warp", "taichi", "cupy")
PEERS = FRAMEWORKS[1:]
STEP_WORKLOADS = {**WORKLOADS, **CUDA_WORKLOADS}
#: Run order. Taichi's fast-math n-body re-initializes Taichi, so it comes last.
RUN_ORDER = ("copy", "saxpy", "saxpy_26", "particles", "nbody", "jacobi", "cloth", "launch",
             "launch_prepared", "nbody_fast")  # fmt: skip
KERNEL_ROWS = ("saxpy", "saxpy_26", "particles", "nbody", "nbody_fast", "jacobi", "cloth")
COMPILE_ROWS = {
    "cold_compile": ("cold compile [ms]", 1e3),
    "cold_start": ("cold start [s]", 1.0),
    "warm_compile": ("warm compile [ms]", 1e3),
    "warm_start": ("warm start [s]", 1.0),
}
ALL = (*RUN_ORDER, "graph", "leaks", "compile")
#: The graph row's target: a 100-kernel step replayed as one graph this much faster.
GRAPH_TARGET = 5.0
RESULTS = Path(__file__).resolve().parent / "results"
PROCESS_REPS = 3
#: The share of the copy bandwidth kdsl's saxpy at 2^26 must reach.
BANDWIDTH_TARGET = 0.9


def device_problem(device: str) -> str | None:
    """Why ``device`` cannot be benchmarked, or None when it can."""
    if device == "cpu":
        return None
    kind, _, index = device.partition(":")
    if kind != "cuda" or not (index or "0").isdigit():
        return f"unknown device {device!r} (expected cuda:N)"
    import kdsl

    count = kdsl.get_cuda_device_count()
    if count == 0:
        return "no CUDA device (CuPy sees none)"
    if int(index or 0) >= count:
        return f"no CUDA device {device} ({count} present)"
    return None


def _release_memory(device: str) -> None:
    """Drop the last workload's arrays and hand CuPy's cached blocks back to the device."""
    gc.collect()
    if device != "cpu" and "cupy" in sys.modules:
        sys.modules["cupy"].get_default_memory_pool().free_all_blocks()


def run_steps(
    order: list[str], mods: dict[str, Any], device: str, quick: bool, reps: int | None
) -> dict[str, dict[str, Cell]]:
    """Every step workload in ``order`` for every framework in ``mods``."""
    cells: dict[str, dict[str, Cell]] = {}
    for wname in order:
        w = STEP_WORKLOADS[wname]
        ins = w.inputs(quick)
        want = w.reference(ins)
        row = cells.setdefault(wname, {})
        for f, m in mods.items():
            if isinstance(m, str):
                row[f] = Cell(status=m)
            else:
                row[f] = harness.run_step(w, m, device, quick, reps, ins, want)
            c = row[f]
            unit = "us" if w.kind == "launch" else "ms"
            text = harness.format_cell(c, unit) + (f" {unit}" if c.stats is not None else "")
            text = c.extra.get("error", "")[:300] or text
            print(f"  {wname:16s} {f:7s} {text}", flush=True)
        del ins, want
        _release_memory(device)
    return cells


def run_compile(mod: Any, device: str, quick: bool) -> dict[str, Cell]:
    """Cold and warm compile and start of the n-body module, in fresh processes."""
    if isinstance(mod, str):
        return {k: Cell(status=mod) for k in COMPILE_ROWS}
    if not hasattr(mod, "start_script"):
        return {k: Cell(status="n/a") for k in COMPILE_ROWS}
    got: dict[str, list[float]] = {k: [] for k in COMPILE_ROWS}
    try:
        for _ in range(1 if quick else PROCESS_REPS):
            with (
                tempfile.TemporaryDirectory(prefix="bench-cache-") as cache,
                tempfile.TemporaryDirectory(prefix="bench-script-") as workdir,
            ):
                src, env = mod.start_script(cache, START_BODIES, device)
                # The driver's PTX JIT cache starts empty too, and persists for the warm run.
                env = {**env, "CUDA_CACHE_PATH": str(Path(workdir) / "cuda-jit-cache")}
                for when in ("cold", "warm"):  # the same script path and cache dir
                    out = harness.run_script(src, env, workdir=workdir)
                    got[f"{when}_compile"].append(out["first_s"])
                    got[f"{when}_start"].append(out["first_epoch"] - out["spawn_epoch"])
    except Exception as e:
        return {k: Cell(status=harness.short_error(e), extra=harness.error_details(e))
                for k in COMPILE_ROWS}  # fmt: skip
    return {k: Cell(Stats.of(v)) for k, v in got.items()}


# -- the table ------------------------------------------------------------------------
class Notes:
    """Numbered notes for cells that failed, so the table stays narrow; cells failing
    with the same message share a note."""

    def __init__(self) -> None:
        self.where: dict[str, list[str]] = {}  # message -> the cells that gave it

    def ref(self, who: str, detail: str) -> int:
        """The number of the note for ``detail``, now also naming ``who``."""
        detail = " ".join(detail.split())
        self.where.setdefault(detail, []).append(who)
        return list(self.where).index(detail) + 1

    def lines(self, width: int = 200) -> list[str]:
        """One line per note, cut to ``width`` characters."""
        out = []
        for k, (detail, whos) in enumerate(self.where.items(), 1):
            text = f"[{k}] {', '.join(whos)}: {detail}"
            out.append(text if len(text) <= width else text[: width - 3] + "...")
        return out


def _size(wname: str, quick: bool) -> int:
    w = STEP_WORKLOADS[wname]
    return w.quick_size if quick else w.size


def _median(cell: Cell | None) -> float | None:
    ok = cell is not None and cell.stats is not None and cell.status == "ok"
    return cell.stats.median if ok else None


def cell_text(cell: Cell | None, scale: float, notes: Notes, who: str) -> str:
    """A narrow table cell: the median times ``scale``, a status, or a note reference."""
    if cell is None:
        return "-"
    v = _median(cell)
    if v is not None:
        v *= scale
        return f"{v:.3g}" if v < 1000 else f"{v:.0f}"
    if cell.status in ("not installed", "n/a"):
        return cell.status
    kind = "wrong" if cell.status.startswith("wrong") else "error"
    return f"{kind} [{notes.ref(who, cell.extra.get('error') or cell.status)}]"


def _yes(ok: bool, why: str = "") -> str:
    return ("yes" if ok else "no") + (f" ({why})" if why else "")


class Table:
    """Builds the summary rows and keeps the outcome of every target."""

    def __init__(self, cells: dict[str, dict[str, Cell]], sizes: dict[str, int]) -> None:
        self.cells = cells
        self.sizes = sizes
        self.notes = Notes()
        self.rows: list[list[str]] = []
        self.met: list[bool] = []

    def add(self, title: str, texts: list[str], best: str, ratio: str, target: str,
            ok: bool | None) -> None:  # fmt: skip
        self.rows.append([title, *texts, best, ratio, target])
        if ok is not None:
            self.met.append(ok)

    def compare(
        self, title: str, wname: str, scale: float, limit: Any = None, has_target: bool = True
    ) -> None:
        """A lower-is-better row; ``limit(kdsl)`` gives (met, why) for its own target
        (None: not measurable), by default kdsl at least as fast as the fastest peer."""
        row = self.cells.get(wname, {})
        texts = [cell_text(row.get(f), scale, self.notes, f"{f} {wname}") for f in FRAMEWORKS]
        mine = _median(row.get("kdsl"))
        peers = {f: _median(row.get(f)) for f in PEERS}
        peers = {f: t for f, t in peers.items() if t is not None}
        best = min(peers, key=peers.get) if peers else "-"
        ratio = "-" if mine is None or not peers else f"{peers[best] / mine:.2f}x"
        kdsl = row.get("kdsl")
        if not has_target:
            verdict = None
        elif mine is None:  # kdsl failing a row with a target misses it
            failed = kdsl is not None and kdsl.status.startswith(("error", "wrong"))
            verdict = (False, "kdsl failed") if failed else None
        elif limit is None:
            verdict = (mine <= peers[best], "") if peers else None
        else:
            verdict = limit(mine)
        target = "-" if verdict is None else _yes(*verdict)
        self.add(title, texts, best, ratio, target, None if verdict is None else verdict[0])

    def gbs(self, wname: str, f: str, bytes_per_elem: int) -> float | None:
        t = _median(self.cells.get(wname, {}).get(f))
        return None if t is None else bytes_per_elem * self.sizes[wname] / t / 1e9

    def build(self) -> None:
        cells = self.cells
        copy_gbs = self.gbs("copy", "cupy", 8) if "copy" in cells else None
        if "copy" in cells:
            cupy = cells["copy"].get("cupy")
            text = (cell_text(cupy, 1.0, self.notes, "cupy copy") if copy_gbs is None
                    else f"{copy_gbs:.0f}")  # fmt: skip
            self.add("d2d copy 2^26 [GB/s]", ["-", "-", "-", text], "-", "-", "-", None)
        for wname in KERNEL_ROWS:
            if wname in cells:
                self.compare(f"{STEP_WORKLOADS[wname].title} [ms]", wname, 1e3)
        raw = _median(cells.get("launch", {}).get("cupy"))

        def vs_raw(mine: float) -> tuple[bool, str] | None:
            return None if raw is None else (mine <= raw, "<=cupy")

        if "launch" in cells:
            self.compare("launch [us]", "launch", 1e6, vs_raw)
        if "launch_prepared" in cells:
            self.compare("prepared launch [us]", "launch_prepared", 1e6, vs_raw)
        if "saxpy_26" in cells:
            rates = {f: self.gbs("saxpy_26", f, 12) for f in FRAMEWORKS}
            texts = ["-" if g is None else f"{g:.0f}" for g in rates.values()]
            mine = rates["kdsl"]
            if mine is None or copy_gbs is None:
                self.add("saxpy 2^26 [GB/s]", texts, "copy", "-", "-", None)
            else:
                share = mine / copy_gbs
                ok = share >= BANDWIDTH_TARGET
                why = f">={BANDWIDTH_TARGET:.0%} copy"
                self.add("saxpy 2^26 [GB/s]", texts, "copy", f"{share:.2f}", _yes(ok, why), ok)
        if "graph" in cells:
            from suite.graph_step import graph_title

            cell = cells["graph"].get("kdsl")
            mine = _median(cell)
            text = cell_text(cell, 1.0, self.notes, "kdsl graph")
            ok = None if mine is None else mine >= GRAPH_TARGET
            self.add(f"{graph_title(cell)} [x]", [text, "-", "-", "-"], "-", "-",
                     "-" if ok is None else _yes(ok, f">={GRAPH_TARGET:.0f}x"), ok)  # fmt: skip
        from suite.leaks import COUNTS, leak_row

        for name in COUNTS:
            if f"leak_{name}" in self.cells:
                title, text, target, _ = leak_row(name, self.cells[f"leak_{name}"].get("kdsl"))
                ok = None if target == "-" else target.startswith("yes")
                self.add(title, [text, "-", "-", "-"], "-", "-", target, ok)
        warp = _median(cells.get("cold_compile", {}).get("warp"))

        def vs_warp(mine: float) -> tuple[bool, str] | None:
            return None if warp is None else (mine <= warp / 4, "<=warp/4")

        for key, (title, scale) in COMPILE_ROWS.items():
            if key in cells:
                cold = key == "cold_compile"
                self.compare(title, key, scale, vs_warp, has_target=cold)


def print_summary(
    cells: dict[str, dict[str, Cell]], meta: dict[str, Any], sizes: dict[str, int]
) -> None:
    """The compact end-of-run summary: header lines, the table, notes, the tally."""
    table = Table(cells, sizes)
    table.build()
    print()
    print(f"== kdsl GPU benchmark: {meta['device_name']} ({meta['device']}) ==")
    print("; ".join(f"{f} {v}" for f, v in meta["versions"].items()))
    headers = ["workload [unit]", *FRAMEWORKS, "best peer", "kdsl vs best", "target met"]
    harness.print_table(headers, table.rows)
    for line in table.notes.lines():
        print(line)
    from suite.leaks import print_details

    print_details(cells)
    kind = "quick" if meta["quick"] else "full"
    print(f"targets met: {sum(table.met)} of {len(table.met)}; {kind} run in "
          f"{meta['elapsed_s']:.0f} s; medians")  # fmt: skip
    print("kdsl vs best > 1x: kdsl faster; in the GB/s row, kdsl's share of the copy bandwidth")


def main() -> int:
    """Parse the arguments, run the selected workloads, print the table, write JSON."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="small sizes, one compile rep")
    p.add_argument("--only", default=",".join(ALL), help=f"comma list of {', '.join(ALL)}")
    p.add_argument("--frameworks", default=",".join(FRAMEWORKS))
    p.add_argument("--reps", type=int, default=None, help="timed samples (default per workload)")
    p.add_argument("--json", type=Path, default=None)
    p.add_argument("--device", default="cuda:0", help="cuda:N (cpu: a dry run of the script)")
    p.add_argument("--skip-compile", action="store_true", help="leave out the compile rows")
    args = p.parse_args()

    only = [w.strip() for w in args.only.split(",") if w.strip()]
    chosen = [f.strip() for f in args.frameworks.split(",") if f.strip()]
    unknown = [w for w in only if w not in ALL]
    bad = [f for f in chosen if f not in FRAMEWORKS]
    if unknown or bad:
        p.error(f"unknown workloads {unknown} or frameworks {bad}")
    problem = device_problem(args.device)
    if problem is not None:
        print(f"bench_cuda: {problem}; nothing measured.", file=sys.stderr)
        return 1

    import kdsl

    mods = harness.load_impls(chosen)
    if args.device == "cpu" and "cupy" in mods:
        mods["cupy"] = "n/a"
    versions = {f: (m if isinstance(m, str) else m.version()) for f, m in mods.items()}
    for f, v in versions.items():
        print(f"{f}: {v}", flush=True)
    order = [w for w in RUN_ORDER if w in only]
    start = time.perf_counter()
    cells = run_steps([w for w in order if w != "copy"], mods, args.device, args.quick, args.reps)
    if "copy" in order:
        # The yardstick of the GB/s row: measured even when CuPy is not compared.
        cupy = mods.get("cupy") or (
            "n/a" if args.device == "cpu" else harness.load_impls(["cupy"])["cupy"]
        )
        yard = run_steps(["copy"], {"cupy": cupy}, args.device, args.quick, args.reps)
        cells["copy"] = yard["copy"]
    if "graph" in only and not isinstance(mods.get("kdsl", "x"), str):
        from suite.graph_step import run_graph

        cells["graph"] = {"kdsl": run_graph(args.device, args.quick, args.reps)}
        print(f"  {'graph':16s} kdsl    {harness.format_cell(cells['graph']['kdsl'], 'x')}")
    if "leaks" in only and not isinstance(mods.get("kdsl", "x"), str):
        from suite.leaks import run_leaks

        for k, c in run_leaks(args.device, args.quick).items():
            cells[k] = {"kdsl": c}
        print(f"  {'leaks':16s} kdsl    done", flush=True)
    if "compile" in only and not args.skip_compile:
        for f, m in mods.items():
            got = run_compile(m, args.device, args.quick)
            for k, c in got.items():
                cells.setdefault(k, {})[f] = c
            cold, warm = got["cold_compile"], got["warm_compile"]
            text = cold.extra.get("error", "")[:300] or (
                f"cold {harness.format_cell(cold, 'ms')} ms, warm {harness.format_cell(warm, 'ms')} ms"
            )
            print(f"  {'compile':16s} {f:7s} {text}", flush=True)
    elapsed = time.perf_counter() - start

    dev = kdsl.get_device(args.device)
    meta = {
        "command": " ".join(sys.argv),
        "quick": args.quick,
        "elapsed_s": elapsed,
        "device": args.device,
        "device_name": dev.name if dev.is_cuda else "cpu (dry run)",
        "versions": versions,
        "sizes": {w: _size(w, args.quick) for w in order},
        "compile_bodies": START_BODIES,
    }
    print_summary(cells, meta, meta["sizes"])
    path = args.json or RESULTS / f"cuda-{time.strftime('%Y%m%d-%H%M%S')}.json"
    harness.save_json(harness.to_json(cells, meta), path)
    return harness.exit_status(cells, "bench_cuda")


if __name__ == "__main__":
    raise SystemExit(main())
