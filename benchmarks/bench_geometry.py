"""Geometry queries, kdsl beside Warp: BVH builds and queries, triangle meshes.

    python benchmarks/bench_geometry.py [--section bvh|mesh|marching_cubes|volume]
        [--boxes 200000] [--tris 200000] [--queries 1000000] [--mc-nodes 256]
        [--samples 10000000] [--stores 1000000] [--reps 3] [--device cpu|cuda:0] [--json PATH]

Each section is a function returning rows; ``main`` runs the sections asked for, prints
one table per section and writes every row to benchmarks/results/geometry.json.

BVH section: ``--boxes`` random boxes (centres uniform in the unit cube, half sizes up
to 0.002) built by each kdsl constructor and by Warp's (its CPU default, ``"sah"``,
and ``"median"``; on a GPU ``"lbvh"``), then ``--queries`` box queries (half size
0.01) and rays (random starts in the cube, random directions, ``max_dist`` 0.05)
counting the items each meets. Times are medians of ``--reps`` runs after a warm-up
(compiles excluded). Every kdsl tree must give exactly Warp's total hit count; a
mismatch exits 1 with the reason.

Mesh section (``bench_geometry_mesh.py``, which also runs alone): the bumpy
cube-sphere of about ``--tris`` triangles, ``--queries`` closest points and rays
(closest and any hit), a move-and-refit; kdsl beside Warp, and Embree for rays.

Marching cubes section (``bench_geometry_mc.py``): two 256^3 fields (a bumpy sphere,
a gyroid), ``surface(field, 0.0)`` with a reusable context; kdsl beside Warp.

Volume section (``bench_geometry_volume.py``): a 256^3 sphere SDF narrow band,
``--samples`` trilinear samples (in the box, in the band) and ``--stores`` stores.
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

from bench_geometry_mc import marching_cubes_section, print_marching_cubes
from bench_geometry_mesh import mesh_section, print_mesh
from bench_geometry_volume import print_volume, volume_section
from suite.harness import median_seconds

RESULTS = Path(__file__).resolve().parent / "results" / "geometry.json"




@wp.kernel
def kd_box_hits(bvh: wp.uint64, lo: wp.array(dtype=wp.vec3), hi: wp.array(dtype=wp.vec3),
                out: wp.array(dtype=int)):  # fmt: skip
    i = wp.tid()
    q = wp.bvh_query_aabb(bvh, lo[i], hi[i])
    k = int(0)  # noqa: UP018, RUF046 - the Warp spelling of a loop-carried int
    n = int(0)  # noqa: UP018, RUF046
    while wp.bvh_query_next(q, k):
        n += 1
    out[i] = n


@wp.kernel
def kd_ray_hits(bvh: wp.uint64, start: wp.array(dtype=wp.vec3), d: wp.array(dtype=wp.vec3),
                max_t: float, out: wp.array(dtype=int)):  # fmt: skip
    i = wp.tid()
    q = wp.bvh_query_ray(bvh, start[i], d[i])
    k = int(0)  # noqa: UP018, RUF046
    n = int(0)  # noqa: UP018, RUF046
    while wp.bvh_query_next(q, k, max_t):
        n += 1
    out[i] = n


def _warp_kernels(warp):
    @warp.kernel
    def box_hits(bvh: warp.uint64, lo: warp.array(dtype=warp.vec3),
                 hi: warp.array(dtype=warp.vec3), out: warp.array(dtype=int)):  # fmt: skip
        i = warp.tid()
        q = warp.bvh_query_aabb(bvh, lo[i], hi[i])
        k = int(0)  # noqa: UP018, RUF046
        n = int(0)  # noqa: UP018, RUF046
        while warp.bvh_query_next(q, k):
            n += 1
        out[i] = n

    @warp.kernel
    def ray_hits(bvh: warp.uint64, start: warp.array(dtype=warp.vec3),
                 d: warp.array(dtype=warp.vec3), max_t: float,
                 out: warp.array(dtype=int)):  # fmt: skip
        i = warp.tid()
        q = warp.bvh_query_ray(bvh, start[i], d[i])
        k = int(0)  # noqa: UP018, RUF046
        n = int(0)  # noqa: UP018, RUF046
        while warp.bvh_query_next(q, k, max_t):
            n += 1
        out[i] = n

    return box_hits, ray_hits


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
    max_t = 0.05
    sync = wp.synchronize if dev != "cpu" else (lambda: None)
    rows, totals = [], {}

    def kv(a):
        return wp.array(a, dtype=wp.vec3, device=dev)

    klo, khi, kqlo, kqhi, krs, krd = map(kv, (lo, hi, qlo, qhi, rs, rd))
    out = wp.zeros(m, dtype=int, device=dev)
    for cons in args.constructors:
        bvh = wp.Bvh(klo, khi, constructor=cons)
        row = {"section": "bvh", "side": "kdsl", "constructor": cons, "boxes": n, "queries": m}
        row["build_s"] = median_seconds(lambda cons=cons: wp.Bvh(klo, khi, constructor=cons),
                                   args.reps, sync)  # fmt: skip
        row["refit_s"] = median_seconds(bvh.refit, args.reps, sync)
        for name, kernel, inputs in (
            ("aabb", kd_box_hits, [bvh.id, kqlo, kqhi, out]),
            ("ray", kd_ray_hits, [bvh.id, krs, krd, max_t, out]),
        ):
            row[f"{name}_s"] = median_seconds(
                lambda k=kernel, i=inputs: wp.launch(k, dim=m, inputs=i, device=dev),
                args.reps, sync,
            )  # fmt: skip
            totals[(cons, name)] = int(out.numpy().sum())
            row[f"{name}_hits"] = totals[(cons, name)]
        rows.append(row)
    try:
        import warp
    except ImportError:
        warp = None
    if warp is not None:
        warp.config.quiet = True
        box_hits, ray_hits = _warp_kernels(warp)
        wdev = "cpu" if dev == "cpu" else dev

        def wv(a):
            return warp.array(a, dtype=warp.vec3, device=wdev)

        wlo, whi, wqlo, wqhi, wrs, wrd = map(wv, (lo, hi, qlo, qhi, rs, rd))
        wout = warp.zeros(m, dtype=int, device=wdev)
        wsync = warp.synchronize
        for cons in ("sah", "median") if dev == "cpu" else ("lbvh", "sah"):
            wb = warp.Bvh(wlo, whi, constructor=cons)
            row = {"section": "bvh", "side": "warp", "constructor": cons, "boxes": n,
                   "queries": m}  # fmt: skip
            row["build_s"] = median_seconds(lambda cons=cons: warp.Bvh(wlo, whi, constructor=cons),
                                       args.reps, wsync)  # fmt: skip
            row["refit_s"] = median_seconds(wb.refit, args.reps, wsync)
            for name, kernel, inputs in (
                ("aabb", box_hits, [wb.id, wqlo, wqhi, wout]),
                ("ray", ray_hits, [wb.id, wrs, wrd, max_t, wout]),
            ):
                row[f"{name}_s"] = median_seconds(
                    lambda k=kernel, i=inputs: warp.launch(k, dim=m, inputs=i, device=wdev),
                    args.reps, wsync,
                )  # fmt: skip
                row[f"{name}_hits"] = int(wout.numpy().sum())
            rows.append(row)
        want = {"aabb": rows[-1]["aabb_hits"], "ray": rows[-1]["ray_hits"]}
        for (cons, name), got in totals.items():
            if got != want[name]:
                sys.exit(f"kdsl {cons} tree: {got} {name} hits, Warp {want[name]}")
    return rows


def _print_bvh(rows: list[dict]) -> None:
    print(f"{'side':<5} {'constructor':<12} {'build ms':>9} {'refit ms':>9} "
          f"{'1M aabb ms':>11} {'1M ray ms':>10}")  # fmt: skip
    for r in rows:
        scale = 1e6 / r["queries"] * 1e3  # per million queries, in ms
        print(f"{r['side']:<5} {r['constructor']:<12} {1e3 * r['build_s']:9.1f} "
              f"{1e3 * r['refit_s']:9.2f} {r['aabb_s'] * scale:11.1f} {r['ray_s'] * scale:10.1f}")  # fmt: skip


SECTIONS = {
    "bvh": (bvh_section, _print_bvh),
    "mesh": (mesh_section, print_mesh),
    "marching_cubes": (marching_cubes_section, print_marching_cubes),
    "volume": (volume_section, print_volume),
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
    p.add_argument("--constructors", default="lbvh,median,sah")
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
