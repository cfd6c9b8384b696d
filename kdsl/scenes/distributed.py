"""Run a grid scene cut into strips over torch.distributed ranks (one strip a rank).

    torchrun --nproc-per-node 2 -m kdsl.scenes.distributed --scene heat --grid 256 --check
    torchrun --nproc-per-node 4 -m kdsl.scenes.distributed --device cuda --grid 8192 --json r.json

Each rank owns one row strip (``kdsl.scenes.strips``) on its device: the CPU (gloo)
or ``cuda:LOCAL_RANK`` (NCCL, kdsl launching on torch's stream so kernels and NCCL
transfers are ordered). ``--check`` also runs the undivided scene on rank 0 and
compares the gathered state with it bit for bit. Rank 0 prints one summary line and
writes ``--json``. Every collective has the process group's timeout (``--timeout``):
a rank that dies or stalls makes the others fail with a ``HaloError`` carrying torch's
message, never hang.
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import os
import sys
import time
from typing import Any

import numpy as np

from kdsl.scenes.binding import SceneError
from kdsl.scenes.halo import TorchHalo, torch_distributed


def init_process_group(device: str, timeout_s: float) -> str:
    """Join torchrun's process group (gloo for ``cpu``, NCCL for ``cuda``); returns this
    rank's kdsl device (``"cpu"`` or ``"cuda:LOCAL_RANK"``)."""
    dist = torch_distributed()
    import torch

    if "RANK" not in os.environ:
        raise SceneError("run under torchrun (no RANK/WORLD_SIZE in the environment)")
    if device == "cuda":
        local = int(os.environ.get("LOCAL_RANK", 0))
        if local >= torch.cuda.device_count():
            raise SceneError(
                f"local rank {local} has no GPU (torch sees {torch.cuda.device_count()})"
            )
        torch.cuda.set_device(local)
        backend, kdsl_device = "nccl", f"cuda:{local}"
    elif device == "cpu":
        backend, kdsl_device = "gloo", "cpu"
    else:
        raise SceneError(f"--device is cpu or cuda, not {device!r}")
    timeout = datetime.timedelta(seconds=timeout_s)
    if not dist.is_initialized():
        dist.init_process_group(backend, timeout=timeout)
    return kdsl_device


def run_strips(scene: Any, steps: int, dt: float) -> dict[str, Any]:
    """Step strip scene ``scene`` ``steps`` times; the wall time (all ranks finished)
    and the global error against the reference."""
    import kdsl as wp

    halo = scene.halo
    scene.step(dt)  # compiles the kernels and warms the exchange; not timed
    wp.synchronize_device(scene.device)
    halo.reduce_max(0.0)  # a barrier that works on every backend
    start = time.perf_counter()
    for _ in range(steps - 1):
        scene.step(dt)
    wp.synchronize_device(scene.device)
    halo.reduce_max(0.0)
    seconds = time.perf_counter() - start
    return {"seconds": seconds, "timed_steps": steps - 1, "error": scene.global_error()}


def matches_single_device(scene: Any, steps: int, dt: float) -> bool:
    """Whether the gathered strips equal the undivided scene after ``steps`` steps, bit
    for bit (rank 0 runs the undivided scene; every rank gets the answer)."""
    import kdsl as wp
    from kdsl.scenes import scene_class

    x, v = scene.global_state()
    same = True
    if scene.halo.rank == 0:
        whole = scene_class(scene.name)(
            wp, precision=scene.precision, integrator=scene.integrator, device=scene.device,
            **scene.params,
        )  # fmt: skip
        for _ in range(steps):
            whole.step(dt)
        wx, wv = whole.state()
        same = _bitwise_equal(x, wx) and (v is None or _bitwise_equal(v, wv))
    return scene.halo.reduce_max(0.0 if same else 1.0) == 0.0


def _bitwise_equal(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and a.tobytes() == b.tobytes()


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m kdsl.scenes.distributed", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    p.add_argument("--scene", default="heat", help="heat or wave")
    p.add_argument("--grid", type=int, default=256, help="interior points per side")
    p.add_argument("--steps", type=int, default=20)
    p.add_argument("--dt", type=float, default=None, help="default: the scene's, made stable")
    p.add_argument("--integrator", default=None)
    p.add_argument("--precision", default="f32", choices=["f32", "f64"])
    p.add_argument("--device", default="cpu", help="cpu (gloo) or cuda (NCCL)")
    p.add_argument("--timeout", type=float, default=120.0, help="seconds for any collective")
    p.add_argument("--check", action="store_true", help="compare with one device, bit for bit")
    p.add_argument("--json", default=None, help="rank 0 writes the results here")
    return p


def stable_dt(cls: Any, grid: int) -> float:
    """The scene's default dt, or half the explicit stability limit where the grid is finer."""
    h = 1.0 / (grid + 1)
    # Heat: explicit Euler needs dt <= h^2 / (4 D); wave: the CFL limit c dt / h <= 1 / sqrt(2).
    bound = h * h / 4.0 if cls.name == "heat" else h / 2.0**0.5
    return min(cls.default_dt, 0.5 * bound)


def main(argv: list[str] | None = None) -> int:
    """Entry point under torchrun (see the module docstring)."""
    import kdsl as wp
    from kdsl.scenes.cli import write_json
    from kdsl.scenes.strips import strip_scene_class

    args = _parser().parse_args(argv)
    if args.steps < 2:
        raise SceneError(f"--steps must be at least 2 (the first is not timed), not {args.steps}")
    cls = strip_scene_class(args.scene)
    device = init_process_group(args.device, args.timeout)
    halo = TorchHalo()
    dt = args.dt if args.dt is not None else stable_dt(cls, args.grid)
    # On a GPU, kdsl's launches and NCCL's transfers go on one stream (torch's): ordered
    # without host syncs.
    on_gpu = device.startswith("cuda")
    with wp.ScopedStream(wp.stream_from_torch(device)) if on_gpu else contextlib.nullcontext():
        scene = cls(wp, halo, precision=args.precision, integrator=args.integrator,
                    device=device, grid=args.grid)  # fmt: skip
        result = run_strips(scene, args.steps, dt)
        if args.check:
            result["bitwise_equal"] = matches_single_device(scene, args.steps, dt)
    result.update(scene=args.scene, grid=args.grid, steps=args.steps, dt=dt, ranks=halo.size,
                  device=args.device, precision=args.precision,
                  integrator=scene.integrator)  # fmt: skip
    if halo.rank == 0:
        cells = args.grid * args.grid * result["timed_steps"]
        result["cell_updates_per_s"] = cells / result["seconds"] if result["seconds"] else None
        line = " ".join(f"{k}={result[k]}" for k in sorted(result))
        print(f"kdsl.scenes.distributed: {line}", flush=True)
        if args.json:
            write_json(args.json, result)
    torch_distributed().destroy_process_group()
    return 0 if result.get("bitwise_equal", True) else 1


if __name__ == "__main__":
    try:
        sys.exit(main())
    except SceneError as e:  # bad arguments or setup: the reason, not a traceback
        print(f"kdsl.scenes.distributed: error: {e}", file=sys.stderr)
        sys.exit(2)
