"""The cost of handing PyTorch tensors and JAX arrays to kernels: the interop guide's benchmark.

    python benchmarks/bench_interop.py [--iters 1000] [--reps 7] [--n 1024] [--json PATH]

Each iteration launches saxpy on two PyTorch tensors, getting the kernel arguments
in one of four ways (Warp's ``benchmark_interop_torch`` compares the middle three):

- ``reuse arrays``: ``from_torch`` once, before the loop (the recommended baseline);
- ``from_torch(...)``: new ``array`` objects every iteration;
- ``from_torch(..., return_ctype=True)``: new lightweight descriptors every iteration;
- ``direct from torch``: the tensors themselves (``__cuda_array_interface__`` on a
  GPU, DLPack / ``__array_interface__`` on the CPU).

Two more rows time the other direction and JAX:

- ``to_torch(...)``: one ``to_torch`` of an array per iteration (no launch);
- ``jax_kernel call``: one call of a jitted JAX function that runs a scale kernel
  through XLA's FFI (``jax_kernel``), waited for (``block_until_ready``); the
  ``jax.jit`` of the same scale in plain JAX is printed as a reference.

It runs for kdsl and, when it imports, Warp, on the CPU and (when PyTorch sees one)
the first GPU, and prints microseconds per iteration (host overhead: the kernel is
tiny). The frameworks' cells of one row are timed in turn, repetition by
repetition, so load on a shared host hits them alike. Results go to
benchmarks/results/interop.json.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

import torch
from suite.harness import Cell, Stats, print_table, save_json, to_json

import kdsl

RESULTS = Path(__file__).resolve().parent / "results" / "interop.json"
METHODS = ("reuse arrays", "from_torch(...)", "from_torch(..., return_ctype=True)",
           "direct from torch")  # fmt: skip


@kdsl.kernel
def saxpy(x: kdsl.array(dtype=float), y: kdsl.array(dtype=float), a: float):
    i = kdsl.tid()
    y[i] = a * x[i] + y[i]


def _warp() -> tuple[Any, Any] | None:
    """Warp and its saxpy kernel, or None when Warp is not usable here."""
    try:
        import warp
    except Exception:  # not installed, or a broken install
        return None
    warp.config.quiet = True
    warp.init()

    @warp.kernel
    def warp_saxpy(x: warp.array(dtype=float), y: warp.array(dtype=float), a: float):
        i = warp.tid()
        y[i] = a * x[i] + y[i]

    return warp, warp_saxpy


def _loop(wp: Any, kernel: Any, method: str, device: str, n: int, iters: int) -> Callable:
    """One timed step: ``iters`` iterations of argument conversion + launch."""
    tdev = "cpu" if device == "cpu" else "cuda:0"
    x = torch.arange(n, dtype=torch.float32, device=tdev)
    y = torch.ones(n, dtype=torch.float32, device=tdev)
    sync = torch.cuda.synchronize if device != "cpu" else (lambda: None)
    launch = wp.launch

    if method == "reuse arrays":
        xw, yw = wp.from_torch(x), wp.from_torch(y)

        def step() -> None:
            for _ in range(iters):
                launch(kernel, dim=n, inputs=[xw, yw, 1.0], device=device)
            sync()

    elif method == "from_torch(...)":

        def step() -> None:
            for _ in range(iters):
                xw, yw = wp.from_torch(x), wp.from_torch(y)
                launch(kernel, dim=n, inputs=[xw, yw, 1.0], device=device)
            sync()

    elif method == "from_torch(..., return_ctype=True)":

        def step() -> None:
            for _ in range(iters):
                xc = wp.from_torch(x, return_ctype=True)
                yc = wp.from_torch(y, return_ctype=True)
                launch(kernel, dim=n, inputs=[xc, yc, 1.0], device=device)
            sync()

    elif method == "to_torch(...)":
        a = wp.from_torch(x)
        to_torch = wp.to_torch

        def step() -> None:
            for _ in range(iters):
                to_torch(a)

    else:

        def step() -> None:
            for _ in range(iters):
                launch(kernel, dim=n, inputs=[x, y, 1.0], device=device)
            sync()

    return step


def _jax_step(wp: Any, n: int, iters: int) -> Callable:
    """``iters`` calls of a jitted JAX function running a scale kernel through ``jax_kernel``."""
    import jax
    import jax.numpy as jnp

    if wp is None:  # plain JAX: the reference
        fn = jax.jit(lambda a: a * 2.0)
    else:
        make = wp.jax_kernel
        if wp is kdsl:
            scale = kdsl_scale
        else:

            @wp.kernel
            def scale(a: wp.array(dtype=float), s: float, out: wp.array(dtype=float)):
                i = wp.tid()
                out[i] = a[i] * s

        jk = make(scale)
        fn = jax.jit(lambda a: jk(a, 2.0)[0])
    x = jnp.arange(n, dtype=jnp.float32)

    def step() -> None:
        for _ in range(iters):
            fn(x).block_until_ready()

    return step


@kdsl.kernel
def kdsl_scale(a: kdsl.array(dtype=float), s: float, out: kdsl.array(dtype=float)):
    i = kdsl.tid()
    out[i] = a[i] * s


def _interleaved(steps: dict[str, Callable], reps: int, iters: int) -> dict[str, Cell]:
    """Each step timed ``reps`` times, the frameworks in turn (one warm-up call each)."""
    cells: dict[str, Cell] = {}
    live = {}
    for name, step in steps.items():
        try:
            step()
            live[name] = step
        except Exception as e:  # one failing cell must not stop the table
            cells[name] = Cell(status=f"error: {type(e).__name__}: {e}"[:60])
    samples: dict[str, list[float]] = {name: [] for name in live}
    for _ in range(reps):
        for name, step in live.items():
            t0 = time.perf_counter()
            step()
            samples[name].append((time.perf_counter() - t0) / iters)
    for name in live:
        cells[name] = Cell(stats=Stats.of(samples[name]))
    return cells


def run(iters: int, reps: int, n: int) -> dict[str, dict[str, Cell]]:
    """Microbenchmark cells keyed by ``"method [device]"`` then framework."""
    frameworks: dict[str, tuple[Any, Any] | None] = {"kdsl": (kdsl, saxpy), "warp": _warp()}
    devices = ["cpu"] + (["cuda:0"] if torch.cuda.is_available() else [])
    cells: dict[str, dict[str, Cell]] = {}
    for device in devices:
        for method in (*METHODS, "to_torch(...)"):
            steps: dict[str, Callable] = {}
            row = cells[f"{method} [{device}]"] = {}
            for name, fw in frameworks.items():
                if fw is None:
                    row[name] = Cell(status="not installed")
                    continue
                try:
                    steps[name] = _loop(fw[0], fw[1], method, device, n, iters)
                except Exception as e:  # one failing cell must not stop the table
                    row[name] = Cell(status=f"error: {type(e).__name__}: {e}"[:60])
            row.update(_interleaved(steps, reps, iters))
    try:
        import jax  # noqa: F401
    except ImportError:
        return cells
    steps = {name: _jax_step(fw[0], n, iters) for name, fw in frameworks.items() if fw}
    steps["jax.jit (plain JAX)"] = _jax_step(None, n, iters)
    cells["jax_kernel call [cpu]"] = _interleaved(steps, reps, iters)
    return cells


def main() -> None:
    """Run the benchmark, print the table, write JSON."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--iters", type=int, default=1000, help="iterations per timed sample")
    ap.add_argument("--reps", type=int, default=7, help="timed samples per cell")
    ap.add_argument("--n", type=int, default=1024, help="tensor length")
    ap.add_argument("--json", type=Path, default=RESULTS)
    args = ap.parse_args()
    cells = run(args.iters, args.reps, args.n)
    names = ["kdsl", "warp", "jax.jit (plain JAX)"]
    rows = []
    for key, row in cells.items():
        rows.append([key] + [_us(row.get(f)) for f in names])
    print(f"us per iteration (2 tensors of {args.n} float32 + one saxpy launch), median")
    print("(to_torch: one conversion; jax_kernel call: one jitted call of a scale kernel)")
    print_table(["method [device]", *names], rows)
    meta = {"benchmark": "interop", "iters": args.iters, "reps": args.reps, "n": args.n,
            "unit": "seconds per iteration", "torch": torch.__version__}  # fmt: skip
    save_json(to_json(cells, meta), args.json)


def _us(cell: Cell | None) -> str:
    if cell is None or cell.stats is None:
        return "-" if cell is None else cell.status
    return f"{cell.stats.median * 1e6:.2f}"


if __name__ == "__main__":
    main()
