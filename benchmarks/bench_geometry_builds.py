"""Geometry builds alone, kdsl beside Warp: a fresh ``Bvh`` and ``Mesh``, with and
without a collected object's build to take, their ``rebuild``/``refit``, and the hash
grid's rebuild by each of its builds.

    python benchmarks/bench_geometry_builds.py [--device cpu|cuda:0] [--boxes 200000]
        [--cells 129] [--points 200000] [--grid-dim 128] [--reps 25] [--json PATH]

Workloads: ``--boxes`` random boxes (centres uniform in the unit cube, half sizes up
to 0.002), as in ``bench_geometry.py``'s BVH section; the bumpy cube-sphere of
``bench_geometry_mesh.py`` with ``--cells`` cells a side (129: 199,692 faces);
``--points`` uniform points in the unit box in a ``--grid-dim``^3 hash grid, the radius
giving 30 neighbours on average. Rows:

- ``bvh fresh``: ``Bvh(lo, hi)`` over the same arrays each time (kdsl's takes the build
  of the one collected before it, ``kdsl.geometry.recycle``); ``bvh cold``: the same
  with the recycle bin emptied first (kdsl only: every build allocates and prepares its
  own); ``bvh rebuild``: ``rebuild()`` of one BVH (kdsl only: Warp's lbvh has none);
- ``mesh fresh`` / ``mesh cold`` / ``mesh refit``: the same for ``Mesh(points, indices)``;
- ``hash grid <build>``: ``grid.build(points, radius)`` again on one grid, per kdsl
  build (``sort``, the default; ``count``, the counting sort), and Warp's.

Each time is the median of ``--reps`` calls after three warm-up calls, synchronized
after each; ``host`` is the time until the call returned (its issue time on a GPU).
The hash grid builds must give the same point order.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

import kdsl as wp
from kdsl.geometry import hash_grid_build, recycle

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_geometry_mesh import bumpy_cube_sphere

RESULTS = Path(__file__).resolve().parent / "results" / "geometry_builds.json"


def timed(fn: Callable[[], object], sync: Callable[[], None], reps: int) -> tuple[float, float]:
    """(median seconds synchronized, median seconds until ``fn`` returned)."""
    for _ in range(3):
        fn()
    sync()
    total, host = [], []
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        t1 = time.perf_counter()
        sync()
        total.append(time.perf_counter() - t0)
        host.append(t1 - t0)
    return statistics.median(total), statistics.median(host)


def _rows(m, side: str, data: dict, device: str, reps: int, sync) -> list[dict]:
    """The rows of module ``m`` (kdsl or Warp) over ``data``."""
    v3 = lambda a: m.array(a, dtype=m.vec3, device=device)  # noqa: E731
    lo, hi, points, hp = v3(data["lo"]), v3(data["hi"]), v3(data["points"]), v3(data["hp"])
    idx = m.array(data["faces"].ravel(), dtype=m.int32, device=device)
    cons = {"constructor": "lbvh"} if side == "kdsl" or device != "cpu" else {}
    runs: list[tuple[str, Callable[[], object]]] = [("bvh fresh", lambda: m.Bvh(lo, hi, **cons))]
    if side == "kdsl":
        bvh = m.Bvh(lo, hi, **cons)
        runs += [("bvh cold", lambda: (recycle.clear(), m.Bvh(lo, hi, **cons))),
                 ("bvh rebuild", bvh.rebuild)]  # fmt: skip
    mesh = m.Mesh(points, idx)
    runs.append(("mesh fresh", lambda: m.Mesh(points, idx)))
    if side == "kdsl":
        runs.append(("mesh cold", lambda: (recycle.clear(), m.Mesh(points, idx))))
    runs.append(("mesh refit", mesh.refit))
    rows = []
    for name, fn in runs:
        total, host = timed(fn, sync, reps)
        rows.append({"side": side, "step": name, "ms": 1e3 * total, "host_ms": 1e3 * host})
    dim, r = data["grid_dim"], data["radius"]
    builds = ("sort", "count") if side == "kdsl" else ("",)
    orders = []
    for build in builds:
        if side == "kdsl":  # grids made now build this way
            hash_grid_build.counting_sort_on = lambda device, b=build: b == "count"
        grid = m.HashGrid(dim, dim, dim, device=device)
        total, host = timed(lambda g=grid: g.build(hp, r), sync, reps)
        rows.append({"side": side, "step": f"hash grid {build}".strip(), "ms": 1e3 * total,
                     "host_ms": 1e3 * host})  # fmt: skip
        if side == "kdsl":
            orders.append(grid._builder.point_ids.numpy()[: len(data["hp"])])
    if orders and not all(np.array_equal(orders[0], o) for o in orders[1:]):
        sys.exit("the hash grid builds gave different point orders")
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--device", default="cpu")
    p.add_argument("--boxes", type=int, default=200_000)
    p.add_argument("--cells", type=int, default=129, help="cube-sphere cells a side")
    p.add_argument("--points", type=int, default=200_000)
    p.add_argument("--grid-dim", type=int, default=128)
    p.add_argument("--reps", type=int, default=25)
    p.add_argument("--json", type=Path, default=RESULTS)
    args = p.parse_args()
    rng = np.random.default_rng(0)
    c = rng.random((args.boxes, 3)).astype(np.float32)
    h = (rng.random((args.boxes, 3)) * 0.002).astype(np.float32)
    pts, faces = bumpy_cube_sphere(args.cells)
    radius = float((30 / args.points * 3 / (4 * np.pi)) ** (1 / 3))
    data = {"lo": c - h, "hi": c + h, "points": pts, "faces": faces, "grid_dim": args.grid_dim,
            "hp": rng.random((args.points, 3)).astype(np.float32), "radius": radius}  # fmt: skip
    default_count = hash_grid_build.counting_sort_on
    try:
        rows = _rows(wp, "kdsl", data, args.device, args.reps,
                     lambda: wp.synchronize_device(args.device))  # fmt: skip
    finally:
        hash_grid_build.counting_sort_on = default_count
    try:
        import warp
    except ImportError:
        warp = None
    if warp is not None:
        warp.config.quiet = True
        warp.init()
        rows += _rows(warp, "warp", data, args.device, args.reps, warp.synchronize)
    print(f"on {args.device}: {args.boxes:,} boxes, {len(faces):,} faces, {args.points:,} "
          f"points in a {args.grid_dim}^3 grid; median of {args.reps}, ms")  # fmt: skip
    print(f"{'side':<6}{'step':<16}{'ms':>10}{'host ms':>10}")
    for r in rows:
        print(f"{r['side']:<6}{r['step']:<16}{r['ms']:10.3f}{r['host_ms']:10.3f}")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"device": args.device, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
