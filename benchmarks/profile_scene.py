"""Profile the host side of one scene's step: time per step, then cProfile tables.

    python benchmarks/profile_scene.py throw --device cuda --steps 20
    python benchmarks/profile_scene.py ocean --device cuda --binding warp

The scene is built at ``bench_scenes.SIZES``'s size, stepped three times (compiles),
timed over ``--steps`` steps, then profiled over as many and printed sorted by own
time and by cumulative time. ``--binding warp`` runs the same scene file under Warp.
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_scenes import SIZES

from kdsl.scenes.measure import make_scene


def main() -> None:
    """Parse the command line, time and profile the scene's step."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene", choices=sorted(SIZES))
    ap.add_argument("--device", default="cpu", choices=("cpu", "cuda"))
    ap.add_argument("--binding", default="kdsl", choices=("kdsl", "warp"))
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--rows", type=int, default=30, help="rows of each profile table")
    a = ap.parse_args()
    integrator, params, dt, _ = SIZES[a.scene]
    scene = make_scene(a.scene, "f32", integrator, a.device, binding=a.binding, **params)
    wp = scene.wp
    for _ in range(3):
        scene.step(dt)
    wp.synchronize_device(scene.device)
    t = time.perf_counter()
    for _ in range(a.steps):
        scene.step(dt)
    wp.synchronize_device(scene.device)
    per_step = 1e6 * (time.perf_counter() - t) / a.steps
    print(f"{a.scene} {a.binding} {a.device}: {per_step:.1f} us/step")
    prof = cProfile.Profile()
    prof.enable()
    for _ in range(a.steps):
        scene.step(dt)
    wp.synchronize_device(scene.device)
    prof.disable()
    stats = pstats.Stats(prof)
    stats.sort_stats("tottime").print_stats(a.rows)
    stats.sort_stats("cumulative").print_stats(a.rows)


if __name__ == "__main__":
    main()
