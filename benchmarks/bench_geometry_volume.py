"""Sparse volumes, kdsl beside Warp: the ``volume`` section of the geometry benchmark
(``bench_geometry.py --section volume``).

Workload (issue 16): the signed distance to a sphere of radius 100 voxels in a 256^3
index box, stored as a narrow band (the voxels within 4 voxels of the surface, about
1.0M; everything else is the background 4.0), one float32 NanoVDB grid
built with kdsl's builder and loaded by both sides from the same bytes. Timed:

- ``sample``: ``--samples`` (10M) ``volume_sample_f(..., LINEAR)`` at points uniform in
  the 256^3 box (``box``: most fall outside the band, where the descent stops at an
  internal node) and at points within the band (``band``: every sample reads leaves);
- ``store``: ``volume_store_f`` of ``--stores`` (1M) distinct band voxels (at most
  the band's voxel count).

Times are medians of ``--reps`` runs after a warm-up (compiles excluded). Warp's CPU
kernels run on one core, kdsl's on every core the process may run on (pin with
``taskset -c 0`` to compare per core). Before any time is printed, kdsl's samples must
equal Warp's within 1e-6 and the stored grids must be equal; otherwise the run exits 1.
"""

from __future__ import annotations

import sys

import numpy as np
from suite.harness import median_seconds

import kdsl as wp
from kdsl.geometry.nanovdb.builder import build_grid, leaves_from_voxels
from kdsl.geometry.nanovdb.layout import GridType
from kdsl.geometry.nanovdb.reader import read_grids
from kdsl.geometry.volume_record import make_volume_record

SIDE, RADIUS, BAND = 256, 100.0, 4.0


def sphere_band() -> tuple[bytes, np.ndarray]:
    """The grid's bytes and its active voxels (N, 3)."""
    axis = np.arange(SIDE, dtype=np.float32) - (SIDE - 1) / 2
    d2 = axis[:, None, None] ** 2 + axis[None, :, None] ** 2 + axis[None, None, :] ** 2
    sdf = np.sqrt(d2) - np.float32(RADIUS)
    ijk = np.argwhere(np.abs(sdf) < BAND)
    values = sdf[ijk[:, 0], ijk[:, 1], ijk[:, 2]].astype(np.float32)
    leaves = leaves_from_voxels(ijk, values, np.float32(BAND))
    return build_grid(leaves, GridType.FLOAT, np.float32(BAND), np.eye(3), (0.0, 0.0, 0.0)), ijk


class _KdslGrid:
    """The grid on a kdsl device and its kernel id."""

    def __init__(self, data: bytes, device: str) -> None:
        self.info = read_grids(data)[0]
        words = np.frombuffer(self.info.data, np.uint32).copy()  # writable: stores
        self.words = wp.array(words, dtype=wp.uint32, device=device)
        self.id = make_volume_record(self, self.words, self.info, device).id


def volume_kernels(m):
    """The sample and store kernels in module ``m``'s API: kdsl's, or Warp's (the same
    source, as a Warp program ported by ``import kdsl as wp``)."""

    @m.kernel
    def sample(vid: m.uint64, p: m.array(dtype=m.vec3), out: m.array(dtype=float)):
        t = m.tid()
        out[t] = m.volume_sample_f(vid, p[t], 1)

    @m.kernel
    def store(vid: m.uint64, ijk: m.array(dtype=m.vec3i), v: m.array(dtype=float)):
        t = m.tid()
        m.volume_store_f(vid, ijk[t][0], ijk[t][1], ijk[t][2], v[t])

    return sample, store


def _points(rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
    box = rng.uniform(0.0, SIDE, (n, 3)).astype(np.float32)
    d = rng.standard_normal((n, 3)).astype(np.float32)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = RADIUS + rng.uniform(-BAND + 1, BAND - 1, (n, 1)).astype(np.float32)
    return {"box": box, "band": ((SIDE - 1) / 2 + d * r).astype(np.float32)}


def _warp():
    try:
        import warp
    except ImportError:
        return None
    warp.config.quiet = True
    return warp


def volume_section(args) -> list[dict]:
    """Trilinear samples and stores on ``args.device``, kdsl beside Warp."""
    dev, reps = args.device, args.reps
    data, active = sphere_band()
    rng = np.random.default_rng(0)
    grid = _KdslGrid(data, dev)
    kd_sample, kd_store = volume_kernels(wp)
    warp = _warp()
    if warp is not None:
        w_sample, w_store = volume_kernels(warp)
        wvol = warp.Volume(warp.array(np.frombuffer(data, np.uint8), dtype=warp.uint8, device=dev))
    rows = []
    base = {"section": "volume", "device": dev, "voxels": len(active), "bytes": len(data)}
    for name, pts in _points(rng, args.samples).items():
        kp, ko = wp.array(pts, dtype=wp.vec3, device=dev), wp.zeros(len(pts), device=dev)
        row = {**base, "side": "kdsl", "op": f"sample {name}", "n": len(pts)}
        row["s"] = median_seconds(lambda kp=kp, ko=ko: wp.launch(kd_sample, kp.shape[0], device=dev,
                             inputs=[grid.id, kp, ko]), reps, wp.synchronize)  # fmt: skip
        rows.append(row)
        if warp is None:
            continue
        wpts = warp.array(pts, dtype=warp.vec3, device=dev)
        wo = warp.zeros(len(pts), dtype=float, device=dev)
        wrow = {**row, "side": "warp"}
        wrow["s"] = median_seconds(lambda wpts=wpts, wo=wo: warp.launch(w_sample, wpts.shape[0],
                              device=dev, inputs=[wvol.id, wpts, wo]), reps, warp.synchronize)  # fmt: skip
        rows.append(wrow)
        err = np.abs(ko.numpy() - wo.numpy()).max(initial=0.0)
        if err > 1e-6:
            sys.exit(f"sample {name}: kdsl's samples differ from Warp's by up to {err}")
    pick = rng.choice(len(active), min(args.stores, len(active)), replace=False)
    ijk = active[pick].astype(np.int32)
    vals = rng.standard_normal(len(ijk)).astype(np.float32)
    ki, kv = wp.array(ijk, dtype=wp.vec3i, device=dev), wp.array(vals, device=dev)
    row = {**base, "side": "kdsl", "op": "store", "n": len(ijk)}
    row["s"] = median_seconds(lambda: wp.launch(kd_store, len(ijk), device=dev,
                         inputs=[grid.id, ki, kv]), reps, wp.synchronize)  # fmt: skip
    rows.append(row)
    if warp is not None:
        wi = warp.array(ijk, dtype=warp.vec3i, device=dev)
        wv = warp.array(vals, dtype=float, device=dev)
        wrow = {**row, "side": "warp"}
        wrow["s"] = median_seconds(lambda: warp.launch(w_store, len(ijk), device=dev,
                              inputs=[wvol.id, wi, wv]), reps, warp.synchronize)  # fmt: skip
        rows.append(wrow)
        if not np.array_equal(grid.words.numpy().view(np.uint8), wvol.array().numpy()):
            sys.exit("store: kdsl's grid differs from Warp's after the same stores")
    return rows


def print_volume(rows: list[dict]) -> None:
    """The section's table: each operation's time per side, and kdsl's speed-up."""
    r0 = rows[0]
    print(f"{SIDE}^3 sphere SDF band: {r0['voxels']:,} voxels, {r0['bytes'] / 1e6:.1f} MB, "
          f"on {r0['device']}; ms")  # fmt: skip
    print(f"{'op':<12} {'side':<6} {'n':>11} {'ms':>9} {'ns/op':>7}")
    for r in rows:
        print(f"{r['op']:<12} {r['side']:<6} {r['n']:>11,} {1e3 * r['s']:9.1f} "
              f"{1e9 * r['s'] / r['n']:7.1f}")  # fmt: skip
    kdsl_s = {r["op"]: r["s"] for r in rows if r["side"] == "kdsl"}
    ratios = [f"{r['op']} {r['s'] / kdsl_s[r['op']]:.2f}x" for r in rows if r["side"] == "warp"]
    if ratios:
        print("kdsl speed-up over warp: " + ", ".join(ratios))
