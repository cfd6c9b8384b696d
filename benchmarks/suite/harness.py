"""Timing, fresh-process measurements, the results table and the JSON file.

On the CPU every framework's step is synchronous when it returns (the impl modules
make it so: Taichi steps end with ``ti.sync()``), so a step's wall time is its cost.
``measure`` warms up (the first call compiles), then times ``reps`` calls and
keeps going while the total is under ``min_time`` (fast steps get more samples).

On a GPU a step only enqueues work, and the runner carries ``sync`` (the framework's
own wait for its stream or device). ``measure_device`` times batches of back-to-back
steps between two syncs and divides, so launch latency overlaps kernel execution as
in a real loop and every sample ends with the work finished.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
import traceback
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np


@dataclass
class Stats:
    """Timings of one cell, in seconds: median, minimum, spread (max - min) / median."""

    median: float
    min: float
    spread: float
    samples: list[float] = field(default_factory=list)

    @classmethod
    def of(cls, samples: list[float]) -> Stats:
        """Statistics of ``samples`` (seconds)."""
        med = statistics.median(samples)
        spread = (max(samples) - min(samples)) / med if med > 0 else 0.0
        return cls(med, min(samples), spread, list(samples))


@dataclass
class Runner:
    """A workload prepared for one framework: ``step()`` runs one synchronized step on
    the prepared data, ``fetch()`` gives the outputs as NumPy arrays. A launch-overhead
    runner's step makes ``launches`` launches."""

    step: Callable[[], None]
    fetch: Callable[[], dict[str, Any]]
    launches: int = 1
    #: Waits until the work ``step`` enqueued has finished; None when ``step`` is synchronous.
    sync: Callable[[], None] | None = None


@dataclass
class Cell:
    """One framework's result on one workload: timings, or why there are none."""

    stats: Stats | None = None
    error: float | None = None  # relative error against the float64 reference
    status: str = "ok"  # "ok", "not installed", "n/a", "error: ...", "wrong: ..."
    extra: dict[str, Any] = field(default_factory=dict)


def measure(
    step: Callable[[], None],
    reps: int,
    warmup: int = 1,
    min_time: float = 0.3,
    max_reps: int = 200,
    per_call: int = 1,
) -> Stats:
    """Time ``step`` after ``warmup`` untimed calls; seconds per call (``per_call``
    calls of the underlying operation per ``step`` are divided out)."""
    for _ in range(warmup):
        step()
    samples: list[float] = []
    total = 0.0
    while len(samples) < reps or (total < min_time and len(samples) < max_reps):
        t0 = time.perf_counter()
        step()
        dt = time.perf_counter() - t0
        samples.append(dt / per_call)
        total += dt
    return Stats.of(samples)


def median_seconds(
    fn: Callable[[], Any], reps: int, sync: Callable[[], None],
    clock: Callable[[], float] = time.perf_counter,
) -> float:  # fmt: skip
    """The median seconds of ``reps`` calls of ``fn``, each followed by ``sync``, after
    one untimed call (the compile), on ``clock`` (wall time; ``time.process_time`` for
    the process's CPU seconds over all its threads)."""
    fn()
    sync()
    times = []
    for _ in range(reps):
        t = clock()
        fn()
        sync()
        times.append(clock() - t)
    return statistics.median(times)


def measure_device(
    step: Callable[[], None],
    sync: Callable[[], None],
    reps: int,
    warmup: int = 1,
    batch_time: float = 0.01,
    min_time: float = 0.3,
    max_reps: int = 200,
    max_batch: int = 1000,
) -> tuple[Stats, int]:
    """Seconds per ``step`` of asynchronous GPU work, and the batch size used.

    Each sample is ``batch`` back-to-back steps between two ``sync()`` calls, divided
    by ``batch``; the batch is sized from one synchronized step so a sample lasts
    about ``batch_time`` (the sync's own latency then counts for little).
    """
    for _ in range(warmup):
        step()
    sync()
    t0 = time.perf_counter()
    step()
    sync()
    one = time.perf_counter() - t0
    batch = max(1, min(max_batch, int(batch_time / max(one, 1e-7))))
    samples: list[float] = []
    total = 0.0
    while len(samples) < reps or (total < min_time and len(samples) < max_reps):
        t0 = time.perf_counter()
        for _ in range(batch):
            step()
        sync()
        dt = time.perf_counter() - t0
        samples.append(dt / batch)
        total += dt
    return Stats.of(samples), batch


# -- one framework on one workload ------------------------------------------------------
def load_impls(names: list[str]) -> dict[str, Any]:
    """name -> ``suite.<name>_impl`` module, or the status string of one that cannot be used."""
    out: dict[str, Any] = {}
    for name in names:
        try:
            out[name] = importlib.import_module(f"suite.{name}_impl")
        except ModuleNotFoundError as e:
            out[name] = "not installed" if e.name and name.startswith(e.name) else short_error(e)
        except Exception as e:  # a peer that fails to import must not stop the others
            out[name] = short_error(e)
    return out


def copy_inputs(ins: dict) -> dict:
    """A copy of workload inputs (arrays copied) so no framework sees another's writes."""
    return {k: v.copy() if isinstance(v, np.ndarray) else v for k, v in ins.items()}


def run_step(
    w: Any,
    mod: Any,
    device: str,
    quick: bool,
    reps: int | None,
    inputs: dict | None = None,
    want: dict | None = None,
) -> Cell:
    """Prepare, verify (the first step also compiles), then time one framework on ``w``.

    ``inputs`` and ``want`` (the float64 reference) may be given when several
    frameworks share them; a runner with ``sync`` is timed by ``measure_device``.
    """
    make = getattr(mod, "RUNNERS", {}).get(w.runner_name)
    if make is None:
        return Cell(status="n/a")
    pristine = w.inputs(quick) if inputs is None else inputs
    extra: dict[str, Any] = {}
    try:
        runner = make(copy_inputs(pristine), device)
        runner.step()
        if runner.sync is not None:
            runner.sync()
        err = w.error(pristine, runner.fetch(), want)
        if runner.sync is None:
            stats = measure(runner.step, reps or w.reps, per_call=runner.launches)
        else:
            stats, extra["batch"] = measure_device(runner.step, runner.sync, reps or w.reps)
    except Exception as e:  # one failing cell must not end the run
        return Cell(status=short_error(e), extra=error_details(e))
    status = "ok" if err <= w.tolerance else f"wrong: err {err:.1e}"
    return Cell(stats, err, status, extra)


def run_script(
    source: str, env: dict[str, str], timeout: float = 300.0, workdir: str | None = None
) -> dict[str, Any]:
    """Run Python ``source`` in a fresh interpreter; its last stdout line is JSON.

    The source is written to ``workdir``/bench_script.py (a temporary directory when
    None): frontends read kernel source from the file, and a kernel cache keyed by
    source locations only hits when a second run uses the same ``workdir``.
    Adds ``spawn_epoch`` (``time.time()`` just before the process started) so a
    script can report ``first_epoch`` and the caller subtract, and ``process_s``.
    """
    full_env = {**os.environ, **env}
    # As users run: bytecode cached (written by the cold run, read by the warm one). With
    # PYTHONDONTWRITEBYTECODE set in the caller's environment (as on the development
    # host) and a tree without __pycache__, every module a warm first launch imports
    # lazily was compiled from source inside the timed region: the cpu n-body's warm
    # compile took 33 ms instead of 10 (benchmarks/profile_warm_compile.py).
    full_env.pop("PYTHONDONTWRITEBYTECODE", None)
    # The script runs elsewhere: relative PYTHONPATH entries ("." for a checkout) must
    # keep pointing where they did, and this checkout's kdsl comes first.
    repo = str(Path(__file__).resolve().parents[2])
    paths = [str(Path(p).resolve()) for p in full_env.get("PYTHONPATH", "").split(os.pathsep) if p]
    full_env["PYTHONPATH"] = os.pathsep.join(dict.fromkeys([repo, *paths]))
    with tempfile.TemporaryDirectory(prefix="kdsl-bench-") as tmp:
        where = Path(workdir or tmp)
        script = where / "bench_script.py"
        script.write_text(source)
        spawn = time.time()
        t0 = time.perf_counter()
        proc = subprocess.run(
            [sys.executable, str(script)], env=full_env, capture_output=True, text=True,
            timeout=timeout, cwd=where,
        )  # fmt: skip
        wall = time.perf_counter() - t0
    if proc.returncode != 0:
        tail = (proc.stderr or proc.stdout).strip().splitlines()
        raise RuntimeError(tail[-1] if tail else f"exit status {proc.returncode}")
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    out["process_s"] = wall
    out["spawn_epoch"] = spawn
    return out


def failed_checks(cells: dict[str, dict[str, Cell]], framework: str = "kdsl") -> list[str]:
    """``workload: status`` of every cell of ``framework`` that failed or was wrong."""
    return [f"{w}: {row[framework].status}" for w, row in cells.items()
            if framework in row and row[framework].status.startswith(("error", "wrong"))]  # fmt: skip


def exit_status(cells: dict[str, dict[str, Cell]], script: str) -> int:
    """1 (with the reason on stderr) when a kdsl cell failed its check, else 0.

    A benchmark whose kdsl result is wrong or missing must not read as a success.
    """
    failed = failed_checks(cells)
    if failed:
        print(f"{script}: kdsl failed its checks: {'; '.join(failed)}", file=sys.stderr)
        return 1
    return 0


def short_error(exc: BaseException, limit: int = 48) -> str:
    """``error: <Type>: <message>`` cut to ``limit`` characters for a table cell."""
    msg = str(exc).strip().splitlines()
    text = f"{type(exc).__name__}: {msg[0] if msg else ''}"
    return "error: " + (text if len(text) <= limit else text[: limit - 3] + "...")


def error_details(exc: BaseException) -> dict[str, str]:
    """The whole message and the traceback of a failure, for the JSON file."""
    return {
        "error": f"{type(exc).__name__}: {str(exc).strip()}"[:2000],
        "traceback": "".join(traceback.format_exception(exc))[-4000:],
    }


# -- table --------------------------------------------------------------------
def format_cell(cell: Cell | None, unit: str) -> str:
    """A table cell: the median in ``unit`` ("ms", "us", "s", "x", "GB/s"), or the status."""
    if cell is None:
        return "-"
    if cell.stats is None:
        return cell.status
    scale = {"ms": 1e3, "us": 1e6, "s": 1.0, "x": 1.0, "GB/s": 1.0, "%": 1.0}[unit]
    v = cell.stats.median * scale
    text = f"{v:.3g}" if v < 100 else f"{v:.0f}"
    return text if cell.status == "ok" else f"{text} ({cell.status})"


def print_table(headers: list[str], rows: list[list[str]], out=sys.stdout) -> None:
    """A left-aligned first column and right-aligned others, separated by two spaces."""
    widths = [max(len(r[i]) for r in [headers, *rows]) for i in range(len(headers))]

    def line(r: list[str]) -> str:
        cells = [r[0].ljust(widths[0])] + [c.rjust(w) for c, w in zip(r[1:], widths[1:])]
        return "  ".join(cells).rstrip()

    print(line(headers), file=out)
    print("-" * len(line(headers)), file=out)
    for r in rows:
        print(line(r), file=out)


# -- JSON ---------------------------------------------------------------------
def machine() -> dict[str, Any]:
    """What the numbers were measured on."""
    cpu = platform.processor()
    try:
        for ln in Path("/proc/cpuinfo").read_text().splitlines():
            if ln.startswith("model name"):
                cpu = ln.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {
        "python": platform.python_version(),
        "platform": platform.platform(),
        "cpu": cpu,
        "cores": len(os.sched_getaffinity(0))
        if hasattr(os, "sched_getaffinity")
        else os.cpu_count(),
    }


def to_json(cells: dict[str, dict[str, Cell]], meta: dict[str, Any]) -> dict[str, Any]:
    """The whole run as a JSON-ready dict (samples kept, in seconds)."""
    return {
        "meta": {**meta, "machine": machine()},
        "results": {w: {f: asdict(c) for f, c in row.items()} for w, row in cells.items()},
    }


def write_json(data: dict[str, Any], path: Path) -> None:
    """Write ``data`` to ``path`` (parents created)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=1, default=str) + "\n")


def save_json(data: dict[str, Any], path: Path) -> None:
    """``write_json`` and say where the results went."""
    write_json(data, path)
    print(f"wrote {path}")


# -- command lines ---------------------------------------------------------------
def script_parser(doc: str, results: Path, reps: int) -> argparse.ArgumentParser:
    """A benchmark script's parser: its docstring's first line, ``--reps`` (default
    ``reps``) and ``--json`` (default ``results``); the script adds its own options."""
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("--reps", type=int, default=reps)
    parser.add_argument("--json", type=Path, default=results)
    return parser


def script_meta(script: str) -> dict[str, Any]:
    """What a script's JSON records about the run: the command line (as run from the
    repository root), Python's version, the processor and the CPU count."""
    return {
        "command": " ".join(["python", f"benchmarks/{script}", *sys.argv[1:]]),
        "python": sys.version.split()[0],
        "machine": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
    }
