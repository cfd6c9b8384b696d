"""Marching cubes, kdsl beside Warp: the ``marching_cubes`` section of the geometry
benchmark (``bench_geometry.py --section marching_cubes``).

Workload (issue 16): two fields of ``--mc-nodes`` (256) nodes per axis, made with NumPy
before any timing: ``blob``, a sphere of radius 0.35 (of the unit cube the grid spans)
with bumps of a few cells, about 0.4M triangles; and ``gyroid``, the gyroid
``sin x cos y + sin y cos z + sin z cos x`` with a period of 32 cells, a surface through
the whole grid (about 4M triangles). Each side extracts the 0 iso-surface with a
reusable context (``kdsl.MarchingCubes`` / ``warp.geometry.IsoSurfaceMarchingCubes``),
``surface(field, 0.0)`` timed whole: the counting pass, the scan, the read back of the
sizes, the allocation of the outputs and the emitting pass. Times are medians of
``--reps`` runs after a warm-up (compiles excluded). Warp's CPU kernels run on one
core, kdsl's on every core the process may run on (pin with ``taskset`` to compare per
core). Before any time is printed, kdsl's triangles must equal Warp's index for index
and its vertices Warp's within 1e-5; otherwise the run exits 1 with the reason.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys

import numpy as np
from suite.harness import median_seconds

import kdsl as wp


def _fields(n: int) -> dict[str, np.ndarray]:
    x = np.linspace(0.0, 1.0, n, dtype=np.float32)
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij", copy=False)
    bumps = 0.02 * np.sin(40 * X) * np.sin(40 * Y) * np.sin(40 * Z)
    blob = np.sqrt((X - 0.5) ** 2 + (Y - 0.5) ** 2 + (Z - 0.5) ** 2) - 0.35 + bumps
    w = np.float32(2 * np.pi * (n - 1) / 32) * np.stack([X, Y, Z])
    gyroid = (np.sin(w[0]) * np.cos(w[1]) + np.sin(w[1]) * np.cos(w[2])
              + np.sin(w[2]) * np.cos(w[0]))  # fmt: skip
    return {"blob": blob.astype(np.float32), "gyroid": gyroid.astype(np.float32)}


def _warp():
    """warp-lang with its ``warp.geometry`` submodule loaded, or None without it."""
    if importlib.util.find_spec("warp") is None:
        return None
    importlib.import_module("warp.geometry")  # Warp does not import it itself
    warp = sys.modules["warp"]
    warp.config.quiet = True
    return warp


def marching_cubes_section(args) -> list[dict]:
    """Marching cubes of each field on ``args.device``, kdsl beside Warp."""
    n, dev = args.mc_nodes, args.device
    warp = _warp()
    rows = []
    for name, f in _fields(n).items():
        field = wp.array(f, dtype=wp.float32, device=dev)
        mc = wp.MarchingCubes(n, n, n, device=dev)
        row = {"section": "marching_cubes", "side": "kdsl", "field": name, "nodes": n,
               "device": dev}  # fmt: skip
        row["surface_s"] = median_seconds(lambda mc=mc, field=field: mc.surface(field, 0.0),
                                     args.reps, wp.synchronize)  # fmt: skip
        row["verts"], row["tris"] = mc.verts.shape[0], mc.indices.shape[0] // 3
        rows.append(row)
        if warp is None:
            continue
        wfield = warp.array(f, dtype=warp.float32, device=dev)
        iso = warp.geometry.IsoSurfaceMarchingCubes(n, n, n)
        wrow = {**row, "side": "warp"}
        wrow["surface_s"] = median_seconds(lambda iso=iso, wf=wfield: iso.surface(wf, 0.0),
                                      args.reps, warp.synchronize)  # fmt: skip
        wrow["verts"], wrow["tris"] = iso.verts.shape[0], iso.indices.shape[0] // 3
        rows.append(wrow)
        if not np.array_equal(mc.indices.numpy(), iso.indices.numpy()):
            sys.exit(f"{name}: kdsl's triangles differ from Warp's ({row['tris']} vs "
                     f"{wrow['tris']})")  # fmt: skip
        kv, wv = mc.verts.numpy(), iso.verts.numpy()
        err = np.abs(kv - wv).max(initial=0.0)
        # A few float32 ulps of the largest coordinate: a GPU contracts a * b + c into one
        # rounding (FMA) where the other compiler may not.
        if err > 4 * np.finfo(np.float32).eps * max(1.0, float(np.abs(wv).max(initial=0.0))):
            sys.exit(f"{name}: kdsl's vertices differ from Warp's by up to {err}")
    return rows


def print_marching_cubes(rows: list[dict]) -> None:
    """The section's table: each field's surface size and time per side."""
    r0 = rows[0]
    print(f"{r0['nodes']}^3 nodes on {r0['device']}; surface(field, 0.0), ms")
    print(f"{'field':<8} {'side':<6} {'verts':>10} {'tris':>10} {'ms':>9}")
    for r in rows:
        print(f"{r['field']:<8} {r['side']:<6} {r['verts']:>10,} {r['tris']:>10,} "
              f"{1e3 * r['surface_s']:9.1f}")  # fmt: skip
    kdsl_s = {r["field"]: r["surface_s"] for r in rows if r["side"] == "kdsl"}
    ratios = [f"{r['field']} {r['surface_s'] / kdsl_s[r['field']]:.2f}x"
              for r in rows if r["side"] == "warp"]  # fmt: skip
    if ratios:
        print("kdsl speed-up over warp: " + ", ".join(ratios))
