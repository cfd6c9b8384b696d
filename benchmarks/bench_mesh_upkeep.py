"""A mesh's upkeep, kdsl beside Warp: a fresh ``Mesh`` and ``refit()`` after every
vertex moved, on the mesh benchmark's bumpy cube-sphere, and where kdsl's time goes.

    python benchmarks/bench_mesh_upkeep.py [--device cpu] [--tris 200000] [--reps 15]
        [--cpu-seconds] [--json PATH]

Both libraries build a mesh over the same points and indices and refit it after a
kernel scaled every point (as ``bench_geometry_mesh.py``'s refit row: the move is timed
with the refit); the calls alternate between the libraries (and, for kdsl, between
the whole call and its stages) round after round in one process, so a change of load
on a shared host reaches both: compare the ratios, min and median over ``--reps``
rounds. Warp 1.19 runs on one core (its CPU path), kdsl on every core the process may
use; with ``--device cuda:0`` both build and refit on that GPU and every call is timed
to its device's synchronization. The stage rows time kdsl's steps one by one (a refit's check with its read back
and the wide tree's pass; a build's collapse, the wide tree's rebuild (collapse and
first fill) and the vertex copy of a mesh without a wide tree), each called alone.
``--cpu-seconds`` times in the process's CPU seconds (all its threads: the work, which
a shared host's load changes far less than wall time; kdsl's on two threads then
counts both). Prints a table, writes benchmarks/results/mesh_upkeep.json.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import kdsl as wp

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_geometry_mesh import mesh_kernels, workload

RESULTS = Path(__file__).resolve().parent / "results" / "mesh_upkeep.json"


def _synced(fn, sync):
    """``fn`` followed by ``sync`` (the device's work counts in the call's time)."""
    return lambda: (fn(), sync())


def _kdsl_rows(data: dict, device: str) -> dict:
    """The kdsl calls and stages to time (name -> callable)."""
    move = mesh_kernels(wp)[3]
    pts = wp.array(data["points"], dtype=wp.vec3, device=device)
    idx = wp.array(data["faces"].reshape(-1), dtype=wp.int32, device=device)
    moving = wp.array(data["points"], dtype=wp.vec3, device=device)
    mesh = wp.Mesh(moving, idx)

    def move_refit():
        wp.launch(move, dim=moving.shape[0], inputs=[moving, 1.0001], device=device)
        mesh.refit()

    def check():
        mesh._faces.start(mesh.points, mesh.indices)
        mesh._faces.finish()

    calls = {"kdsl fresh Mesh": lambda: wp.Mesh(pts, idx), "kdsl move + refit": move_refit,
             "  refit: check + read back": check}  # fmt: skip
    wide = mesh._wide
    if wide is not None and wide.nodes.shape[0] and hasattr(wide, "_refit_steps"):
        from kdsl.geometry import wide_collapse  # (not in kdsl before session 12)

        calls["  refit: the wide tree's pass"] = wide._refit_steps(mesh.bvh)[0]
        calls["  build: collapse"] = lambda: wide_collapse.collapse(
            mesh.bvh.packed_nodes, idx.shape[0] // 3, wp.get_device("cpu")
        )
        calls["  build: wide rebuild"] = lambda: wide.rebuild(mesh.bvh)
    calls["  build: vertex copy"] = mesh._tree_points.write
    return {k: _synced(fn, lambda: wp.synchronize_device(device)) for k, fn in calls.items()}


def _warp_rows(data: dict, device: str) -> dict:
    """Warp's calls on ``device``, or none without Warp."""
    try:
        import warp
    except ImportError:
        return {}
    warp.config.quiet = True
    move = mesh_kernels(warp)[3]
    pts = warp.array(data["points"], dtype=warp.vec3, device=device)
    idx = warp.array(data["faces"].reshape(-1), dtype=warp.int32, device=device)
    moving = warp.array(data["points"], dtype=warp.vec3, device=device)
    mesh = warp.Mesh(moving, idx)

    def move_refit():
        warp.launch(move, dim=moving.shape[0], inputs=[moving, 1.0001], device=device)
        mesh.refit()

    calls = {"warp fresh Mesh": lambda: warp.Mesh(pts, idx), "warp move + refit": move_refit}
    return {k: _synced(fn, lambda: warp.synchronize_device(device)) for k, fn in calls.items()}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--device", default="cpu")
    p.add_argument("--tris", type=int, default=200_000)
    p.add_argument("--reps", type=int, default=15)
    p.add_argument("--cpu-seconds", action="store_true", help="process CPU time, not wall")
    p.add_argument("--json", type=Path, default=RESULTS)
    args = p.parse_args()
    data = workload(args.tris, 1)
    calls = {**_kdsl_rows(data, args.device), **_warp_rows(data, args.device)}
    for fn in calls.values():  # warm up: compiles, first packings, recycled builds
        fn()
        fn()
    clock = time.process_time if args.cpu_seconds else time.perf_counter
    times = {name: [] for name in calls}
    for _ in range(args.reps):
        for name, fn in calls.items():
            t = clock()
            fn()
            times[name].append(clock() - t)
    rows = [{"name": k, "min_ms": 1e3 * min(v), "median_ms": 1e3 * statistics.median(v)}
            for k, v in times.items()]  # fmt: skip
    by = {r["name"]: r for r in rows}
    unit = "process CPU ms" if args.cpu_seconds else "ms"
    print(f"{len(data['faces'])} faces on {args.device}, {args.reps} rounds; {unit}")
    print(f"{'call':<28} {'min':>8} {'median':>8}")
    for r in rows:
        print(f"{r['name']:<28} {r['min_ms']:8.3f} {r['median_ms']:8.3f}")
    for what in ("fresh Mesh", "move + refit"):
        k, w = by.get(f"kdsl {what}"), by.get(f"warp {what}")
        if k and w:
            print(f"Warp / kdsl, {what}: min {w['min_ms'] / k['min_ms']:.2f}x, "
                  f"median {w['median_ms'] / k['median_ms']:.2f}x")  # fmt: skip
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"device": args.device, "faces": len(data["faces"]), "reps": args.reps,
                                     "clock": unit, "rows": rows}, indent=2))  # fmt: skip


if __name__ == "__main__":
    main()
