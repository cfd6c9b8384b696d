"""Strong and weak scaling of the strip-decomposed heat scene, and peer copies between GPUs.

    python benchmarks/bench_multigpu.py [--grid 8192] [--steps 50] [--max-ranks 8]
                                        [--paths team,torch] [--json PATH]

The heat scene (explicit Euler: one Laplacian and one update a step) cut into row
strips with ghost rows (``kdsl.scenes.strips``), on 1, 2, 4 and 8 ranks up to the GPUs
present (``--max-ranks``), two ways:

- ``team``: one process, one thread and one GPU a strip, ghost rows by ``kdsl.copy``
  between devices (peer to peer where the GPUs allow it; ``DeviceTeam``);
- ``torch``: ``torchrun`` processes, one GPU a rank, ghost rows through NCCL
  (``python -m kdsl.scenes.distributed``).

Strong scaling keeps the ``grid x grid`` problem (efficiency ``t1 / (k tk)``); weak
scaling keeps ``grid^2`` points a rank (the grid side grows as ``sqrt(k)``; efficiency
``t1 / tk``). Peer copies: GB/s of ``kdsl.copy`` from ``cuda:0`` to ``cuda:1`` with peer
access on and off, beside a copy within ``cuda:0`` (bytes moved once).

Without GPUs it runs a smoke version on the CPU (strips on the ``cpu`` device, gloo
processes for ``torch``) at ``--cpu-grid``: the figures then say only that the paths run.
Results go to benchmarks/results/multigpu.json.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from suite.harness import machine, print_table, write_json

import kdsl as wp
from kdsl.scenes.distributed import run_strips, stable_dt
from kdsl.scenes.halo import DeviceTeam
from kdsl.scenes.strips import HeatStrip

RESULTS = Path(__file__).resolve().parent / "results" / "multigpu.json"
ROOT = Path(__file__).resolve().parents[1]


def team_run(devices: list[str], grid: int, steps: int) -> dict[str, Any]:
    """The heat strips stepped by a ``DeviceTeam`` over ``devices``: rank 0's result."""
    dt = stable_dt(HeatStrip, grid)

    def work(halo: Any) -> dict[str, Any]:
        scene = HeatStrip(wp, halo, grid=grid, device=halo.device)
        return run_strips(scene, steps, dt)

    return DeviceTeam(devices, timeout_s=600).run(work)[0]


def torch_run(ranks: int, device: str, grid: int, steps: int) -> dict[str, Any]:
    """The heat strips over ``ranks`` torchrun processes: rank 0's JSON."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "r.json"
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
        cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone",
               f"--nproc-per-node={ranks}", "-m", "kdsl.scenes.distributed", "--scene", "heat",
               "--device", device, "--grid", str(grid), "--steps", str(steps),
               "--json", str(out)]  # fmt: skip
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=900)
        if proc.returncode != 0:
            raise RuntimeError(f"torchrun with {ranks} ranks failed:\n{proc.stderr[-3000:]}")
        return json.loads(out.read_text())


def peer_copies(nbytes: int, reps: int = 10) -> list[dict[str, Any]]:
    """GB/s of copies cuda:0 -> cuda:1 (peer on, off) and cuda:0 -> cuda:0."""
    n = nbytes // 4
    src = wp.zeros(n, dtype=wp.float32, device="cuda:0")
    rows = []
    cases = [("cuda:0 -> cuda:0", "cuda:0", None)]
    if wp.get_cuda_device_count() >= 2:
        cases.append(("cuda:0 -> cuda:1, peer access off", "cuda:1", False))
        if wp.is_peer_access_supported("cuda:1", "cuda:0"):
            cases.append(("cuda:0 -> cuda:1, peer access on", "cuda:1", True))
    for name, dst_dev, peer in cases:
        dst = wp.zeros(n, dtype=wp.float32, device=dst_dev)
        saved = None if peer is None else wp.is_peer_access_enabled("cuda:0", "cuda:1")
        if peer is not None:  # cuda:1 reads or writes cuda:0's memory, and back
            wp.set_peer_access_enabled("cuda:0", "cuda:1", peer)
            wp.set_peer_access_enabled("cuda:1", "cuda:0", peer)
        wp.copy(dst, src)
        wp.synchronize()
        start = time.perf_counter()
        for _ in range(reps):
            wp.copy(dst, src)
        wp.synchronize()
        seconds = (time.perf_counter() - start) / reps
        if peer is not None:
            wp.set_peer_access_enabled("cuda:0", "cuda:1", saved)
            wp.set_peer_access_enabled("cuda:1", "cuda:0", saved)
        rows.append({"copy": name, "bytes": nbytes, "ms": 1e3 * seconds,
                     "GB/s": nbytes / seconds / 1e9})  # fmt: skip
    return rows


def scaling(path: str, counts: list[int], device: str, grid: int, steps: int) -> list[dict]:
    """Strong and weak scaling rows of one path."""
    rows = []
    for kind in ("strong", "weak"):
        base = None
        for k in counts:
            side = grid if kind == "strong" else round(grid * math.sqrt(k))
            devices = [f"cuda:{i}" for i in range(k)] if device == "cuda" else ["cpu"] * k
            r = (
                team_run(devices, side, steps)
                if path == "team"
                else torch_run(k, device, side, steps)
            )
            ms = 1e3 * r["seconds"] / r["timed_steps"]
            base = base or ms
            eff = base / (k * ms) if kind == "strong" else base / ms
            rows.append({"path": path, "scaling": kind, "ranks": k, "grid": side,
                         "ms_per_step": ms, "efficiency": eff, "error": r["error"],
                         "cell_updates_per_s": side * side / (ms * 1e-3)})  # fmt: skip
            print(f"  {path} {kind} {k} ranks, grid {side}: {ms:.3f} ms/step", flush=True)
    return rows


def main() -> int:
    """Run the benchmark (see the module docstring)."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--grid", type=int, default=8192, help="grid side on GPUs (strong scaling)")
    p.add_argument("--cpu-grid", type=int, default=256, help="grid side of the CPU smoke run")
    p.add_argument("--steps", type=int, default=50)
    p.add_argument("--max-ranks", type=int, default=8)
    p.add_argument("--paths", default="team,torch", help="team, torch or both")
    p.add_argument("--copy-mib", type=int, default=256, help="size of the peer copies")
    p.add_argument("--json", default=str(RESULTS))
    args = p.parse_args()
    gpus = wp.get_cuda_device_count()
    device = "cuda" if gpus else "cpu"
    grid = args.grid if gpus else args.cpu_grid
    most = min(args.max_ranks, gpus) if gpus else min(args.max_ranks, 2)
    counts = [k for k in (1, 2, 4, 8) if k <= most]
    paths = [s for s in args.paths.split(",") if s]
    if "torch" in paths:
        try:
            import torch.distributed  # noqa: F401
        except ImportError:
            print("torch is not installed: the torch path is skipped")
            paths.remove("torch")
    rows: list[dict] = []
    for path in paths:
        rows += scaling(path, counts, device, grid, args.steps)
    copies = peer_copies(args.copy_mib << 20) if gpus else []
    print(f"\nheat strips, explicit Euler, {device} ({gpus} GPUs), {args.steps} steps")
    print_table(
        ["path", "scaling", "ranks", "grid", "ms/step", "Gcell/s", "efficiency"],
        [[r["path"], r["scaling"], str(r["ranks"]), str(r["grid"]), f"{r['ms_per_step']:.3f}",
          f"{r['cell_updates_per_s'] / 1e9:.2f}", f"{100 * r['efficiency']:.0f}%"]
         for r in rows],
    )  # fmt: skip
    if copies:
        print()
        print_table(["copy", "MiB", "ms", "GB/s"],
                    [[c["copy"], str(c["bytes"] >> 20), f"{c['ms']:.3f}", f"{c['GB/s']:.1f}"]
                     for c in copies])  # fmt: skip
    meta = {"machine": machine(), "gpus": gpus, "device": device, "steps": args.steps}
    if gpus:
        import cupy

        meta["card"] = cupy.cuda.runtime.getDeviceProperties(0)["name"].decode()
    write_json({"meta": meta, "scaling": rows, "peer_copies": copies}, Path(args.json))
    return 0


if __name__ == "__main__":
    sys.exit(main())
