"""Host builds of NanoVDB volumes, kdsl beside Warp: a 256^3 sphere signed distance field.

    python benchmarks/bench_volume_build.py [--n 256] [--band 3] [--reps 3] [--device cpu]

Three builds of the same field (a sphere of radius ``0.4 n`` voxels in an ``n^3`` grid):

- ``load_from_numpy``: the dense ``n^3`` float32 array, every voxel active;
- ``allocate_by_tiles``: the 8^3 tiles of the narrow band (voxels within ``--band`` of the
  surface), every voxel at the background, as a sparse volume is allocated before
  kernels store its values;
- ``builder (voxels)``: kdsl's NumPy builder given the band's voxels and values (the
  sparse grid in one step; Warp has no such call).

Times are medians of ``--reps`` runs after one warm-up, each ending with the volume on
``--device`` (its bytes validated by kdsl's reader); Warp's rows (warp-lang, when
installed) are its calls of the same names on the same device.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

import kdsl as wp
from kdsl.geometry.nanovdb.builder import build_grid, leaves_from_voxels
from kdsl.geometry.nanovdb.layout import GridType


def sphere_sdf(n: int) -> np.ndarray:
    """The signed distance (in voxels) to a sphere of radius 0.4 n centred in the grid."""
    x = np.arange(n, dtype=np.float32) - (n - 1) / 2
    return np.sqrt(x[:, None, None] ** 2 + x[None, :, None] ** 2 + x[None, None, :] ** 2) - 0.4 * n


def median_time(fn, reps: int) -> float:
    """The median wall time of ``reps`` calls of ``fn`` after one warm-up call (kernel
    compiles, first-touch allocations)."""

    def once() -> float:
        t = time.perf_counter()
        fn()
        return time.perf_counter() - t

    fn()
    return statistics.median([once() for _ in range(reps)])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--n", type=int, default=256)
    p.add_argument("--band", type=float, default=3.0)
    p.add_argument("--reps", type=int, default=3)
    p.add_argument("--device", default="cpu")
    args = p.parse_args()
    sdf = sphere_sdf(args.n)
    band = np.argwhere(np.abs(sdf) < args.band).astype(np.int32)
    values = sdf[tuple(band.T)]
    tiles = np.unique(band & ~7, axis=0)
    h = 1.0 / args.n
    print(
        f"{args.n}^3 sphere SDF: {len(band)} band voxels in {len(tiles)} tiles, device "
        f"{args.device}"
    )
    rows = []

    def kdsl_builder():
        data = build_grid(
            leaves_from_voxels(band, values, np.float32(args.band)),
            GridType.FLOAT,
            args.band,
            np.eye(3) * h,
            (0, 0, 0),
        )
        return wp.Volume(wp.array(np.frombuffer(data, np.uint8), device=args.device))

    sides = [("kdsl", wp)]
    try:
        import warp

        warp.config.quiet = True
        sides.append(("warp", warp))
    except ImportError:
        pass
    for who, m in sides:  # the same calls through each module
        tile_points = m.array(tiles, dtype=m.vec3i, device=args.device)
        calls = {
            "load_from_numpy": lambda m=m: m.Volume.load_from_numpy(
                sdf, voxel_size=h, bg_value=0.0, device=args.device
            ),
            "allocate_by_tiles": lambda m=m, t=tile_points: m.Volume.allocate_by_tiles(
                t, h, float(args.band), device=args.device
            ),
        }
        if m is wp:
            calls["builder (voxels)"] = kdsl_builder
        rows += [(who, name, median_time(call, args.reps)) for name, call in calls.items()]
    for who, what, t in rows:
        print(f"  {who:5s} {what:18s} {t * 1e3:9.1f} ms")


if __name__ == "__main__":
    main()
