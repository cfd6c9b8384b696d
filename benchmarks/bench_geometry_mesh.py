"""Triangle-mesh queries, kdsl beside Warp (and Embree for rays): the mesh section of
the geometry benchmark.

    python benchmarks/bench_geometry_mesh.py [--tris 200000] [--queries 1000000]
        [--reps 3] [--device cpu|cuda:0] [--quick] [--cpu-seconds] [--json PATH]

Workload (issue 15): the bumpy cube-sphere of ``examples/mesh_project.py`` with about
``--tris`` triangles; ``--queries`` points uniform in the box 1.2 times the mesh's,
each asking for its closest point (``mesh_query_point_no_sign``, ``max_dist`` 10: every
point finds a face); as many rays from points in that box in uniform random
directions, asking for the closest hit (``mesh_query_ray``) and for any hit
(``mesh_query_ray_anyhit``), ``max_t`` 1e6; and a refit after every vertex moved (a
kernel scales the points by 1.01, then ``refit()``; the move is timed with it). Each
side also builds its mesh (``Mesh(points, indices)``: the BVH and the record; kdsl's
takes the face boxes and BVH build of the mesh collected before it,
``kdsl.geometry.recycle``; ``cold``, kdsl only, empties that bin before each build).

Times are medians of ``--reps`` runs after a warm-up (compiles excluded). Warp runs on
the same device (on the CPU it uses one core; kdsl uses every core the process may run
on: pin with ``taskset`` to compare per core; ``--cpu-seconds`` times the queries in
the process's CPU seconds instead, summed over its threads: the work per core, which a
shared host's load changes far less than wall time). On the CPU, Embree 4 (through
``embreex``, when installed; one thread, as embreex calls ``rtcIntersect1`` per ray)
answers the same rays. Answers are compared before any time is printed: kdsl's
closest-point distances and ray ``t`` must match Warp's within float32 rounding, and
the hit/miss of every ray must agree with Warp's except for rays within rounding of an
edge; otherwise the run exits 1 with the reason. ``--quick`` shrinks the workload to
about 20k triangles and 100k queries. ``bench_geometry.py`` runs ``mesh_section`` as
its ``mesh`` section; alone, this file writes benchmarks/results/geometry_mesh.json.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np

import kdsl as wp

sys.path.insert(0, str(Path(__file__).resolve().parent))
from suite.harness import median_seconds

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "geometry_mesh.json"
MAX_DIST = 10.0
MAX_T = 1.0e6
#: Rays whose hit/miss may differ between two correct float32 implementations (a ray
#: within rounding of an edge or a silhouette): at most this fraction of the rays.
RAY_DISAGREEMENT = 1.0e-4




def bumpy_cube_sphere(cells: int) -> tuple[np.ndarray, np.ndarray]:
    """The example's mesh generator (``examples/mesh_project.py``), one definition."""
    spec = importlib.util.spec_from_file_location(
        "kdsl_example_mesh_project", ROOT / "examples" / "mesh_project.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.bumpy_cube_sphere(cells)


def workload(tris: int, queries: int, seed: int = 0) -> dict[str, np.ndarray]:
    """The mesh (``points``, ``faces``) and the queries: ``points_q``, ``ray_start``,
    ``ray_dir`` (unit), as float32/int32 NumPy arrays."""
    cells = max(1, round((tris / 12) ** 0.5))
    pts, faces = bumpy_cube_sphere(cells)
    rng = np.random.default_rng(seed)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    centre, half = (lo + hi) / 2, (hi - lo) / 2 * 1.2

    def box_points(n):
        return (centre + half * rng.uniform(-1, 1, (n, 3))).astype(np.float32)

    d = rng.normal(size=(queries, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return {"points": pts, "faces": faces, "points_q": box_points(queries),
            "ray_start": box_points(queries), "ray_dir": d.astype(np.float32)}  # fmt: skip


def mesh_kernels(m):
    """The benchmark's kernels written against module ``m`` (kdsl or warp): one source,
    both compilers."""

    @m.kernel
    def closest(mesh: m.uint64, xs: m.array(dtype=m.vec3), face: m.array(dtype=m.int32),
                dist: m.array(dtype=float)):  # fmt: skip
        i = m.tid()
        x = xs[i]
        q = m.mesh_query_point_no_sign(mesh, x, MAX_DIST)
        face[i] = -1
        if q.result:
            face[i] = q.face
            dist[i] = m.length(m.mesh_eval_position(mesh, q.face, q.u, q.v) - x)

    @m.kernel
    def ray(mesh: m.uint64, start: m.array(dtype=m.vec3), d: m.array(dtype=m.vec3),
            face: m.array(dtype=m.int32), t: m.array(dtype=float)):  # fmt: skip
        i = m.tid()
        q = m.mesh_query_ray(mesh, start[i], d[i], MAX_T)
        face[i] = -1
        if q.result:
            face[i] = q.face
            t[i] = q.t

    @m.kernel
    def anyhit(mesh: m.uint64, start: m.array(dtype=m.vec3), d: m.array(dtype=m.vec3),
               hit: m.array(dtype=m.int32)):  # fmt: skip
        i = m.tid()
        hit[i] = 0
        if m.mesh_query_ray_anyhit(mesh, start[i], d[i], MAX_T):
            hit[i] = 1

    @m.kernel
    def move(points: m.array(dtype=m.vec3), scale: float):
        i = m.tid()
        points[i] = points[i] * scale

    return closest, ray, anyhit, move


def median_cpu_seconds(fn, reps: int, sync) -> float:
    """``median_seconds`` in the process's CPU seconds (all its threads)."""
    return median_seconds(fn, reps, sync, clock=time.process_time)


def _run_side(m, name: str, data: dict, device: str, reps: int, sync,
              query_timer=median_seconds) -> tuple[dict, dict]:  # fmt: skip
    """Time one library's build, queries (with ``query_timer``) and refit; returns the
    row and its answers."""
    closest, ray, anyhit, move = mesh_kernels(m)
    n = len(data["points_q"])

    def v3(a):
        return m.array(a, dtype=m.vec3, device=device)

    pts, idx = v3(data["points"]), m.array(data["faces"].reshape(-1), dtype=m.int32, device=device)
    xs, rs, rd = v3(data["points_q"]), v3(data["ray_start"]), v3(data["ray_dir"])
    face = m.zeros(n, dtype=m.int32, device=device)
    dist = m.zeros(n, dtype=float, device=device)
    rface = m.zeros(n, dtype=m.int32, device=device)
    rt = m.zeros(n, dtype=float, device=device)
    hit = m.zeros(n, dtype=m.int32, device=device)
    row = {"section": "mesh", "side": name, "device": device, "tris": len(data["faces"]),
           "queries": n}  # fmt: skip
    row["build_s"] = median_seconds(lambda: m.Mesh(pts, idx), reps, sync)
    if m is wp:  # without the collected mesh's face boxes and BVH build (kdsl.geometry.recycle)
        row["cold_s"] = median_seconds(lambda: (wp.geometry.recycle.clear(), m.Mesh(pts, idx)),
                                       reps, sync)  # fmt: skip
    mesh = m.Mesh(pts, idx)
    launches = {
        "closest": (closest, [mesh.id, xs, face, dist]),
        "ray": (ray, [mesh.id, rs, rd, rface, rt]),
        "anyhit": (anyhit, [mesh.id, rs, rd, hit]),
    }
    for key, (kernel, inputs) in launches.items():
        row[f"{key}_s"] = query_timer(
            lambda k=kernel, i=inputs: m.launch(k, dim=n, inputs=i, device=device), reps, sync
        )
    answers = {"face": face.numpy().copy(), "dist": dist.numpy().copy(),
               "ray_face": rface.numpy().copy(), "ray_t": rt.numpy().copy(),
               "anyhit": hit.numpy().copy()}  # fmt: skip
    moving = v3(data["points"])  # its own copy: the motion must not reach the query mesh
    moved_mesh = m.Mesh(moving, idx)
    npts = len(data["points"])

    def move_refit():
        m.launch(move, dim=npts, inputs=[moving, 1.0001], device=device)
        moved_mesh.refit()

    row["refit_s"] = median_seconds(move_refit, reps, sync)
    return row, answers


def _embree_row(data: dict, timer=median_seconds) -> tuple[dict, dict] | None:
    """Embree's closest and any hits of the same rays (``embreex``), or None without it."""
    try:
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh
    except ImportError:
        return None
    n = len(data["ray_start"])
    row = {"section": "mesh", "side": "embree", "device": "cpu", "tris": len(data["faces"]),
           "queries": n}  # fmt: skip

    def build():
        scene = rtcore_scene.EmbreeScene()
        TriangleMesh(scene, data["points"], data["faces"])
        return scene

    row["build_s"] = median_seconds(build, 3, lambda: None)
    scene = build()
    start, d = data["ray_start"], data["ray_dir"]
    out = {}

    def closest():
        out["closest"] = scene.run(start, d, output=1)

    def any_hit():
        out["anyhit"] = scene.run(start, d, query="OCCLUDED")

    row["ray_s"] = timer(closest, 1, lambda: None)
    row["anyhit_s"] = timer(any_hit, 1, lambda: None)
    res = out["closest"]
    t = np.where(res["primID"] >= 0, res["tfar"], 0.0).astype(np.float32)
    return row, {"ray_face": res["primID"], "ray_t": t, "anyhit": (out["anyhit"] >= 0)}


def check_answers(ours: dict, ref: dict, ref_name: str) -> list[str]:
    """Where kdsl's answers differ from a reference's beyond float32 rounding (one line
    each; empty when they agree)."""
    problems = []
    if "dist" in ref:
        found = (ours["face"] >= 0) != (ref["face"] >= 0)
        if found.any():
            problems.append(f"closest point: {int(found.sum())} points found by one side only")
        both = (ours["face"] >= 0) & (ref["face"] >= 0)
        err = np.abs(ours["dist"][both] - ref["dist"][both]).max(initial=0.0)
        if err > 1e-5:
            problems.append(f"closest point: distances differ by up to {err:.2e}")
    n = len(ours["ray_face"])
    hit, ref_hit = ours["ray_face"] >= 0, ref["ray_face"] >= 0
    for key, a, b in (("closest hit", hit, ref_hit), ("any hit", ours["anyhit"] > 0,
                                                        ref["anyhit"] > 0)):  # fmt: skip
        if (a != b).sum() > RAY_DISAGREEMENT * n:
            problems.append(f"{key}: {int((a != b).sum())} of {n} rays disagree on hit/miss")
    both = hit & ref_hit
    rel = np.abs(ours["ray_t"][both] - ref["ray_t"][both]) / np.maximum(ref["ray_t"][both], 1e-3)
    bad = int((rel > 1e-4).sum())
    if bad > RAY_DISAGREEMENT * n:
        problems.append(f"closest hit: {bad} rays hit at another t")
    return [f"kdsl vs {ref_name}, {p}" for p in problems]


def mesh_section(args) -> list[dict]:
    """Mesh build, closest point, closest/any ray hit and refit: kdsl, Warp, Embree."""
    tris = getattr(args, "tris", 200_000)
    queries = args.queries
    if getattr(args, "quick", False):
        tris, queries = min(tris, 20_000), min(queries, 100_000)
    dev = args.device
    data = workload(tris, queries)
    sync = (lambda: None) if dev == "cpu" else (lambda: wp.synchronize_device(dev))
    timer = median_seconds
    if dev == "cpu" and getattr(args, "cpu_seconds", False):
        timer = median_cpu_seconds
    row, ours = _run_side(wp, "kdsl", data, dev, args.reps, sync, timer)
    row["query_clock"] = "cpu" if timer is median_cpu_seconds else "wall"
    rows, problems = [row], []
    try:
        import warp
    except ImportError:
        warp = None
    if warp is not None and not getattr(args, "no_warp", False):
        warp.config.quiet = True
        warp.init()
        wrow, theirs = _run_side(warp, "warp", data, dev, args.reps, warp.synchronize, timer)
        rows.append(wrow)
        problems += check_answers(ours, theirs, "Warp")
    if dev == "cpu" and not getattr(args, "no_embree", False):
        embree = _embree_row(data, timer)
        if embree is not None:
            rows.append(embree[0])
            problems += check_answers(ours, embree[1], "Embree")
    if problems:
        sys.exit("\n".join(problems))
    return rows


def print_mesh(rows: list[dict]) -> None:
    """The mesh section's table: times per million queries, and kdsl's speed-ups."""
    r0 = rows[0]
    clock = "CPU ms (all threads)" if r0.get("query_clock") == "cpu" else "ms"
    print(f"bumpy cube-sphere, {r0['tris']:,} triangles, {r0['queries']:,} queries on "
          f"{r0['device']}; ms, queries in {clock} scaled to 1M")  # fmt: skip
    cols = ("build", "cold", "closest", "ray", "anyhit", "refit")
    print(f"{'side':<7}" + "".join(f"{c + ' ms':>12}" for c in cols))
    for r in rows:
        scale = {c: 1e3 * (1e6 / r["queries"] if c in ("closest", "ray", "anyhit") else 1)
                 for c in cols}  # fmt: skip
        cells = [f"{r[c + '_s'] * scale[c]:12.1f}" if c + "_s" in r else f"{'-':>12}" for c in cols]
        print(f"{r['side']:<7}" + "".join(cells))
    for r in rows[1:]:
        ratios = [f"{c} {r[c + '_s'] / r0[c + '_s']:.2f}x" for c in cols if c + "_s" in r]
        print(f"kdsl speed-up over {r['side']}: " + ", ".join(ratios))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--tris", type=int, default=200_000)
    p.add_argument("--queries", type=int, default=1_000_000)
    p.add_argument("--reps", type=int, default=3)
    p.add_argument("--device", default="cpu")
    p.add_argument("--quick", action="store_true", help="about 20k triangles, 100k queries")
    p.add_argument("--no-warp", action="store_true")
    p.add_argument("--no-embree", action="store_true")
    p.add_argument("--cpu-seconds", action="store_true",
                   help="time the CPU queries in process CPU seconds (per-core work)")  # fmt: skip
    p.add_argument("--json", type=Path, default=RESULTS)
    args = p.parse_args()
    print(f"on {args.device} ({platform.processor() or platform.machine()}, "
          f"{wp.utils.buffers.host_threads()} host threads)")  # fmt: skip
    rows = mesh_section(args)
    print_mesh(rows)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"device": args.device, "sections": {"mesh": rows}}, indent=2))
    print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
