"""Geometry queries, kdsl beside Warp: BVH builds and queries, triangle meshes.

    python benchmarks/bench_geometry.py [--section bvh|mesh|marching_cubes|volume|hash_grid]
        [--boxes 200000] [--tris 200000] [--queries 1000000] [--mc-nodes 256]
        [--samples 10000000] [--stores 1000000] [--points 200000] [--neighbours 30]
        [--grid-dim 128] [--reps 3] [--device cpu|cuda:0] [--cpu-seconds] [--json PATH]

Each section is a function returning rows; ``main`` runs the sections asked for, prints
one table per section and writes every row to benchmarks/results/geometry.json.

BVH section: ``--boxes`` random boxes (centres uniform in the unit cube, half sizes up
to 0.002) built by each kdsl constructor and by Warp's (its CPU default, ``"sah"``,
and ``"median"``; on a GPU ``"lbvh"``), then ``--queries`` box queries (half size
0.01) and rays (random starts in the cube, random directions, ``max_dist`` 0.05)
counting the items each meets. Times are medians of ``--reps`` runs after a warm-up
(compiles excluded). ``build`` is a fresh ``Bvh`` over the same box arrays each time:
kdsl's takes the build of the one collected before it (``kdsl.geometry.recycle``);
``cold`` (kdsl only) empties that bin first, so every build allocates and prepares
its own. Every kdsl tree must give exactly Warp's total hit count; a mismatch exits 1
with the reason.

Mesh section (``bench_geometry_mesh.py``, which also runs alone): the bumpy
cube-sphere of about ``--tris`` triangles, ``--queries`` closest points and rays
(closest and any hit), a move-and-refit; kdsl beside Warp, and Embree for rays.

Marching cubes section (``bench_geometry_mc.py``): two 256^3 fields (a bumpy sphere,
a gyroid), ``surface(field, 0.0)`` with a reusable context; kdsl beside Warp.

Volume section (``bench_geometry_volume.py``): a 256^3 sphere SDF narrow band,
``--samples`` trilinear samples (in the box, in the band) and ``--stores`` stores.

Hash grid section (``bench_geometry_hashgrid.py``, which also runs alone): ``--points``
uniform points in the unit box, the radius giving ``--neighbours`` neighbours on
average, a ``--grid-dim``^3 grid: rebuild and the seed's neighbour-sum query; kdsl
beside Warp, and Numba and Taichi on the CPU when installed.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
from pathlib import Path

import numpy as np

import kdsl as wp

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_geometry_hashgrid import hash_grid_section, print_hash_grid
from bench_geometry_mc import marching_cubes_section, print_marching_cubes
from bench_geometry_mesh import mesh_section, print_mesh
from bench_geometry_volume import print_volume, volume_section
from suite.harness import median_seconds

RESULTS = Path(__file__).resolve().parent / "results" / "geometry.json"


def _hit_kernels(m):
    """The box- and ray-query kernels in module ``m``'s API (kdsl or warp): each thread
    counts the items its query reports."""

    @m.kernel
    def box_hits(bvh: m.uint64, lo: m.array(dtype=m.vec3), hi: m.array(dtype=m.vec3),
                 out: m.array(dtype=int)):  # fmt: skip
        i = m.tid()
        q = m.bvh_query_aabb(bvh, lo[i], hi[i])
        k = int(0)  # noqa: UP018, RUF046 - the Warp spelling of a loop-carried int
        n = int(0)  # noqa: UP018, RUF046
        while m.bvh_query_next(q, k):
            n += 1
        out[i] = n

    @m.kernel
    def ray_hits(bvh: m.uint64, start: m.array(dtype=m.vec3), d: m.array(dtype=m.vec3),
                 max_t: float, out: m.array(dtype=int)):  # fmt: skip
        i = m.tid()
        q = m.bvh_query_ray(bvh, start[i], d[i])
        k = int(0)  # noqa: UP018, RUF046
        n = int(0)  # noqa: UP018, RUF046
        while m.bvh_query_next(q, k, max_t):
            n += 1
        out[i] = n

    return box_hits, ray_hits


def _bvh_rows(m, side: str, constructors, data, max_t: float, dev: str, reps: int,
              sync) -> list[dict]:  # fmt: skip
    """Build, refit and query times of module ``m``'s Bvh per constructor, over ``data``
    (box lowers and uppers, query box lowers and uppers, ray starts and directions)."""
    box_hits, ray_hits = _hit_kernels(m)
    lo, hi, qlo, qhi, rs, rd = (m.array(a, dtype=m.vec3, device=dev) for a in data)
    queries = len(data[2])
    out = m.zeros(queries, dtype=int, device=dev)
    rows = []
    for cons in constructors:
        bvh = m.Bvh(lo, hi, constructor=cons)
        row = {"section": "bvh", "side": side, "constructor": cons, "boxes": len(data[0]),
               "queries": queries}  # fmt: skip
        row["build_s"] = median_seconds(lambda cons=cons: m.Bvh(lo, hi, constructor=cons),
                                        reps, sync)  # fmt: skip
        if m is wp:  # without a collected BVH's build (kdsl.geometry.recycle)
            row["cold_s"] = median_seconds(
                lambda cons=cons: (wp.geometry.recycle.clear(), m.Bvh(lo, hi, constructor=cons)),
                reps, sync,
            )  # fmt: skip
        row["refit_s"] = median_seconds(bvh.refit, reps, sync)
        for name, kernel, inputs in (
            ("aabb", box_hits, [bvh.id, qlo, qhi, out]),
            ("ray", ray_hits, [bvh.id, rs, rd, max_t, out]),
        ):
            row[f"{name}_s"] = median_seconds(
                lambda k=kernel, i=inputs: m.launch(k, dim=queries, inputs=i, device=dev),
                reps, sync,
            )  # fmt: skip
            row[f"{name}_hits"] = int(out.numpy().sum())
        rows.append(row)
    return rows


def bvh_section(args) -> list[dict]:
    """BVH build per constructor and box/ray queries, kdsl beside Warp."""
    rng = np.random.default_rng(0)
    n, m, dev = args.boxes, args.queries, args.device
    c = rng.random((n, 3)).astype(np.float32)
    h = (rng.random((n, 3)) * 0.002).astype(np.float32)
    lo, hi = c - h, c + h
    qc = rng.random((m, 3)).astype(np.float32)
    qlo, qhi = qc - np.float32(0.01), qc + np.float32(0.01)
    rs = rng.random((m, 3)).astype(np.float32)
    rd = rng.normal(size=(m, 3)).astype(np.float32)
    rd /= np.linalg.norm(rd, axis=1, keepdims=True)
    data, max_t = (lo, hi, qlo, qhi, rs, rd), 0.05
    sync = wp.synchronize if dev != "cpu" else (lambda: None)
    rows = _bvh_rows(wp, "kdsl", args.constructors, data, max_t, dev, args.reps, sync)
    try:
        import warp
    except ImportError:
        return rows
    warp.config.quiet = True
    constructors = ("sah", "median") if dev == "cpu" else ("lbvh", "sah")
    wrows = _bvh_rows(warp, "warp", constructors, data, max_t, dev, args.reps, warp.synchronize)
    for r in rows:
        for name in ("aabb", "ray"):
            if r[f"{name}_hits"] != wrows[-1][f"{name}_hits"]:
                sys.exit(f"kdsl {r['constructor']} tree: {r[f'{name}_hits']} {name} hits, "
                         f"Warp {wrows[-1][f'{name}_hits']}")  # fmt: skip
    return rows + wrows


def _print_bvh(rows: list[dict]) -> None:
    print(f"{'side':<5} {'constructor':<12} {'build ms':>9} {'cold ms':>8} {'refit ms':>9} "
          f"{'1M aabb ms':>11} {'1M ray ms':>10}")  # fmt: skip
    for r in rows:
        scale = 1e6 / r["queries"] * 1e3  # per million queries, in ms
        cold = f"{1e3 * r['cold_s']:8.2f}" if "cold_s" in r else f"{'-':>8}"
        print(f"{r['side']:<5} {r['constructor']:<12} {1e3 * r['build_s']:9.2f} {cold} "
              f"{1e3 * r['refit_s']:9.2f} {r['aabb_s'] * scale:11.1f} {r['ray_s'] * scale:10.1f}")  # fmt: skip


SECTIONS = {
    "bvh": (bvh_section, _print_bvh),
    "mesh": (mesh_section, print_mesh),
    "marching_cubes": (marching_cubes_section, print_marching_cubes),
    "volume": (volume_section, print_volume),
    "hash_grid": (hash_grid_section, print_hash_grid),
}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--section", action="append", choices=sorted(SECTIONS))
    p.add_argument("--boxes", type=int, default=200_000)
    p.add_argument("--tris", type=int, default=200_000, help="the mesh section's triangles")
    p.add_argument("--queries", type=int, default=1_000_000)
    p.add_argument("--mc-nodes", type=int, default=256, help="marching_cubes: nodes per axis")
    p.add_argument("--samples", type=int, default=10_000_000, help="volume: trilinear samples")
    p.add_argument("--stores", type=int, default=1_000_000, help="volume: volume_store calls")
    p.add_argument("--points", type=int, default=200_000, help="hash_grid: particles")
    p.add_argument("--neighbours", type=float, default=30.0,
                   help="hash_grid: mean neighbours (sets the radius)")
    p.add_argument("--grid-dim", type=int, default=128, help="hash_grid: cells per axis")
    p.add_argument("--constructors", default="lbvh,median,sah")
    p.add_argument("--cpu-seconds", action="store_true",
                   help="mesh: time the CPU queries in process CPU seconds (per-core work)")  # fmt: skip
    p.add_argument("--reps", type=int, default=3)
    p.add_argument("--device", default="cpu")
    p.add_argument("--json", type=Path, default=RESULTS)
    args = p.parse_args()
    args.constructors = [
        c for c in args.constructors.split(",") if c in wp.geometry.bvh.CONSTRUCTORS
    ]
    print(f"on {args.device} ({platform.processor() or platform.machine()}, "
          f"{wp.utils.buffers.host_threads()} host threads)")  # fmt: skip
    results = {}
    for name in args.section or sorted(SECTIONS):
        run, show = SECTIONS[name]
        results[name] = run(args)
        print(f"\n[{name}]")
        show(results[name])
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"device": args.device, "sections": results}, indent=2))
    print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
