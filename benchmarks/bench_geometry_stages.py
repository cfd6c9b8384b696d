"""Where a BVH or mesh build and refit spend their time: each step (kernel launch,
allocation, sort, scan, sum, fill, read back, record write), timed alone.

    python benchmarks/bench_geometry_stages.py [--device cpu|cuda:0] [--boxes 200000]
        [--tris 200000] [--reps 5] [--json PATH]

Every step the geometry modules call is wrapped (their module-level names, and
``array.numpy`` / ``array.fill_`` / ``array.zero_`` / ``ObjectRecord.write`` / the
prepared sum, scan and sort ``SumInto``, ``ScanInto``, ``SortKeys`` / a prepared
``Launch.launch``; ``prepare`` rows are launches recorded with ``record_cmd``); only
the outermost step of a nest counts. Two passes per workload: ``sync`` synchronizes the
device after every step, so a step's time is its host work plus its device work;
``issue`` does not, so a step's time is only what it costs the host to enqueue it (on
the CPU the two agree: every step is synchronous). ``total`` is one unwrapped call
with a synchronize at its end. Medians over ``--reps`` calls, after a warm-up call.
The rows print per workload, slowest step first; the JSON holds every row.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path

import numpy as np

import kdsl as wp
from kdsl.geometry import bvh as bvh_mod
from kdsl.geometry import device_tree, lbvh, mesh_refit
from kdsl.geometry import mesh as mesh_mod
from kdsl.runtime.array import array
from kdsl.runtime.launch import Launch
from kdsl.runtime.objects import ObjectRecord
from kdsl.utils.reduce import SumInto
from kdsl.utils.scan import ScanInto
from kdsl.utils.sort import SortKeys

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_geometry_mesh import bumpy_cube_sphere
from suite.harness import median_seconds

RESULTS = Path(__file__).resolve().parent / "results" / "geometry_stages.json"
#: The module-level names of the steps, in the modules that call them.
STEPS = ("launch", "empty", "zeros", "full", "radix_sort_pairs", "array_scan", "array_sum")
MODULES = (bvh_mod, device_tree, lbvh, mesh_mod, mesh_refit)
METHODS = ((array, "numpy"), (array, "fill_"), (array, "zero_"), (ObjectRecord, "write"),
           (SumInto, "__call__"), (ScanInto, "__call__"), (SortKeys, "__call__"),
           (Launch, "launch"))  # fmt: skip


class StepClock:
    """Wraps the steps; while ``on``, adds each outermost step's seconds to ``times``."""

    def __init__(self, sync: Callable[[], None]) -> None:
        self.sync, self.on, self.depth = sync, False, 0
        self.times: dict[str, list[float]] = defaultdict(list)
        self.per_sync = True
        self._undo: list[tuple[object, str, object]] = []

    def _wrap(self, fn: Callable, label: Callable[..., str]) -> Callable:
        def timed(*args, **kwargs):
            if not self.on or self.depth:
                return fn(*args, **kwargs)
            self.depth += 1
            t = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                if self.per_sync:
                    self.sync()
                self.times[label(*args, **kwargs)].append(time.perf_counter() - t)
                self.depth -= 1

        return timed

    def install(self) -> None:
        """Wrap every step (undone by ``remove``)."""

        def launch_label(kernel, *a, **k) -> str:
            verb = "prepare" if k.get("record_cmd") else "launch"
            return f"{verb} {getattr(kernel, 'key', kernel)}"

        def prepared_label(cmd, *a, **k) -> str:
            return f"prepared launch {getattr(cmd.kernel, 'key', cmd.kernel)}"

        for mod in MODULES:
            for name in STEPS:
                fn = getattr(mod, name, None)
                if fn is not None:
                    label = launch_label if name == "launch" else (lambda *a, n=name, **k: n)
                    self._undo.append((mod, name, fn))
                    setattr(mod, name, self._wrap(fn, label))
        for cls, name in METHODS:
            fn = getattr(cls, name)
            self._undo.append((cls, name, fn))
            step = f"{cls.__name__} call" if name == "__call__" else name
            label = prepared_label if cls is Launch else (lambda *a, n=step, **k: n)
            setattr(cls, name, self._wrap(fn, label))

    def remove(self) -> None:
        for owner, name, fn in reversed(self._undo):
            setattr(owner, name, fn)
        self._undo.clear()


def _profile(name: str, fn: Callable[[], object], sync, reps: int) -> list[dict]:
    """The rows of one workload: per step, its median seconds per call of ``fn`` in
    both passes, and the unwrapped total."""
    total = median_seconds(fn, reps, sync)  # also the warm-up call
    passes = {}
    for per_sync in (True, False):
        clock = StepClock(sync)
        clock.per_sync = per_sync
        clock.install()
        try:
            per_rep = []
            for _ in range(reps):
                clock.times.clear()
                clock.on = True
                fn()
                clock.on = False
                sync()
                per_rep.append({k: (sum(v), len(v)) for k, v in clock.times.items()})
        finally:
            clock.remove()
        passes["sync" if per_sync else "issue"] = per_rep
    steps = sorted({k for rep in passes["sync"] for k in rep})
    rows = []
    for step in steps:
        row = {"workload": name, "step": step, "calls": passes["sync"][0].get(step, (0, 0))[1]}
        for key, reps_ in passes.items():
            row[f"{key}_ms"] = 1e3 * statistics.median(r.get(step, (0.0, 0))[0] for r in reps_)
        rows.append(row)
    rows.sort(key=lambda r: -r["sync_ms"])
    rows.append({"workload": name, "step": "total", "calls": 1,
                 "sync_ms": 1e3 * total, "issue_ms": float("nan")})  # fmt: skip
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default="cpu")
    p.add_argument("--boxes", type=int, default=200_000)
    p.add_argument("--tris", type=int, default=200_000)
    p.add_argument("--reps", type=int, default=5)
    p.add_argument("--json", type=Path, default=RESULTS)
    args = p.parse_args()
    device = args.device
    sync = lambda: wp.synchronize_device(device)  # noqa: E731
    rng = np.random.default_rng(0)
    c = rng.random((args.boxes, 3)).astype(np.float32)
    h = (rng.random((args.boxes, 3)) * 0.002).astype(np.float32)
    lo = wp.array(c - h, dtype=wp.vec3, device=device)
    hi = wp.array(c + h, dtype=wp.vec3, device=device)
    cells = max(2, round((args.tris / 12) ** 0.5))  # a cube of 6 cells^2 squares, 2 faces each
    pts, faces = bumpy_cube_sphere(cells)
    points = wp.array(pts, dtype=wp.vec3, device=device)
    indices = wp.array(faces.ravel(), dtype=wp.int32, device=device)
    bvh = wp.Bvh(lo, hi, constructor="lbvh")
    mesh = wp.Mesh(points, indices)
    rows = []
    rows += _profile("bvh build (lbvh)", lambda: wp.Bvh(lo, hi, constructor="lbvh"), sync,
                     args.reps)  # fmt: skip
    rows += _profile("bvh refit", bvh.refit, sync, args.reps)
    rows += _profile(f"mesh build ({len(faces)} faces)", lambda: wp.Mesh(points, indices), sync,
                     args.reps)  # fmt: skip
    rows += _profile("mesh refit", mesh.refit, sync, args.reps)
    current = None
    for r in rows:
        if r["workload"] != current:
            current = r["workload"]
            print(f"\n{current} on {device}, median ms per call")
            print(f"{'step':58s} {'calls':>5s} {'sync ms':>9s} {'issue ms':>9s}")
        print(f"{r['step'][:58]:58s} {r['calls']:5d} {r['sync_ms']:9.3f} {r['issue_ms']:9.3f}")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"device": device, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
