"""Autodiff: backward/forward time ratios and gradient accuracy, kdsl beside Warp.

    python benchmarks/bench_autodiff.py [--quick] [--device cpu|cuda] [--frameworks kdsl,warp]
                                        [--json PATH]

Part 1 times one forward launch and one adjoint launch (``launch(adjoint=True)``)
of three programs written once for both frameworks (n-body forces with a dynamic
inner loop, particle integration, a spring chain with neighbour reads), and prints
backward / forward per framework. kdsl's backward includes its tape counting pass
where a loop needs one; the first launches (compilation) are not timed.

Part 2 differentiates the stiff and extreme cases of ``kdsl.testing.stiff_cases``
under each framework and compares with float64 finite differences.
Results go to benchmarks/results/autodiff-<timestamp>.json.
"""

from __future__ import annotations

import argparse
import importlib
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from suite import harness

RESULTS = Path(__file__).resolve().parent / "results"


def build(wp: Any) -> dict[str, Any]:
    """The timed programs, compiled by ``wp`` (kdsl or warp)."""

    @wp.kernel
    def nbody(pos: wp.array(dtype=wp.vec3), n: int, acc: wp.array(dtype=wp.vec3)):
        i = wp.tid()
        p = pos[i]
        a = wp.vec3(0.0, 0.0, 0.0)
        for j in range(n):
            d = pos[j] - p
            r2 = wp.dot(d, d) + 0.01
            a = a + d * (1.0 / (r2 * wp.sqrt(r2)))
        acc[i] = a

    @wp.kernel
    def particles(x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3), dt: float,
                  x_out: wp.array(dtype=wp.vec3), v_out: wp.array(dtype=wp.vec3)):  # fmt: skip
        i = wp.tid()
        vel = v[i] + wp.vec3(0.0, -9.8, 0.0) * dt
        vel = vel * (1.0 - 0.1 * dt)
        x_out[i] = x[i] + vel * dt
        v_out[i] = vel

    @wp.kernel
    def spring_chain(x: wp.array(dtype=wp.vec3), rest: float, k: float,
                     f: wp.array(dtype=wp.vec3)):  # fmt: skip
        i = wp.tid()
        n = x.shape[0]
        force = wp.vec3(0.0, 0.0, 0.0)
        if i > 0:
            d = x[i - 1] - x[i]
            length = wp.length(d)
            force = force + d * (k * (length - rest) / length)
        if i < n - 1:
            d = x[i + 1] - x[i]
            length = wp.length(d)
            force = force + d * (k * (length - rest) / length)
        f[i] = force

    return {"nbody": nbody, "particles": particles, "spring_chain": spring_chain}


def programs(quick: bool, rng: np.random.Generator) -> dict[str, dict[str, Any]]:
    """Inputs per program: (name, array data or scalar) in parameter order, outputs last."""
    nb = 256 if quick else 2048
    npart = 1 << (14 if quick else 20)
    nchain = 1 << (14 if quick else 20)
    chain = np.zeros((nchain, 3), np.float32)
    chain[:, 0] = np.arange(nchain) * 1.1 + rng.uniform(-0.05, 0.05, nchain)
    return {
        "nbody": {"dim": nb, "inputs": [rng.uniform(-1, 1, (nb, 3)), nb],
                  "outputs": [np.zeros((nb, 3))]},
        "particles": {"dim": npart,
                      "inputs": [rng.uniform(-1, 1, (npart, 3)), rng.uniform(-1, 1, (npart, 3)),
                                 1.0 / 60.0],
                      "outputs": [np.zeros((npart, 3)), np.zeros((npart, 3))]},
        "spring_chain": {"dim": nchain, "inputs": [chain, 1.0, 50.0],
                         "outputs": [np.zeros((nchain, 3))]},
    }  # fmt: skip


def _framework(name: str) -> Any:
    if name == "warp":
        import warp

        warp.config.quiet = True
        warp.init()
        return warp
    return importlib.import_module("kdsl")


def _sync(wp: Any, device: str) -> None:
    if device != "cpu":
        wp.synchronize_device(device)


def time_program(wp: Any, kernel: Any, prog: dict[str, Any], device: str, reps: int) -> dict:
    """Median forward and backward seconds of one program under ``wp``."""

    def arr(a):
        return wp.array(a.astype(np.float32), dtype=wp.vec3, device=device, requires_grad=True)

    inputs = [arr(a) if isinstance(a, np.ndarray) else a for a in prog["inputs"]]
    outputs = [arr(a) for a in prog["outputs"]]
    adj_in = [a.grad if hasattr(a, "grad") else type(a)(0) for a in inputs]
    adj_out = [wp.array(np.ones_like(a).astype(np.float32), dtype=wp.vec3, device=device)
               for a in prog["outputs"]]  # fmt: skip
    dim = prog["dim"]

    def forward():
        wp.launch(kernel, dim=dim, inputs=inputs, outputs=outputs, device=device)
        _sync(wp, device)

    def backward():
        wp.launch(kernel, dim=dim, inputs=inputs, outputs=outputs, adj_inputs=adj_in,
                  adj_outputs=adj_out, adjoint=True, device=device)  # fmt: skip
        _sync(wp, device)

    fwd = harness.measure(forward, reps)
    bwd = harness.measure(backward, reps)
    return {"forward_s": fwd.median, "backward_s": bwd.median,
            "ratio": bwd.median / fwd.median}  # fmt: skip


def accuracy(wp: Any, device: str) -> list[dict]:
    """The stiff-case rows for one framework."""
    from kdsl.testing import stiff_cases

    kernels = stiff_cases.build(wp)
    return [stiff_cases.evaluate(wp, kernels, c, device) for c in stiff_cases.CASES]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="small sizes (a smoke test)")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--frameworks", default="kdsl,warp")
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    rng = np.random.default_rng(1234)
    progs = programs(args.quick, rng)
    ratios: dict[str, dict[str, Any]] = {}
    rows_acc: dict[str, list[dict]] = {}
    for name in args.frameworks.split(","):
        try:
            wp = _framework(name)
        except ImportError as e:
            print(f"{name}: not installed ({e})")
            continue
        kernels = build(wp)
        ratios[name] = {}
        for prog, spec in progs.items():
            try:
                ratios[name][prog] = time_program(wp, kernels[prog], spec, args.device, args.reps)
            except Exception as e:  # one framework's failure must not hide the rest
                ratios[name][prog] = {"error": harness.short_error(e)}
        rows_acc[name] = accuracy(wp, args.device)

    print(f"\nbackward / forward time ({args.device}; median of >= {args.reps} runs)")
    names = list(ratios)
    header = ["program", *[f"{n} fwd ms" for n in names], *[f"{n} bwd ms" for n in names],
              *[f"{n} bwd/fwd" for n in names]]  # fmt: skip
    table = []
    for prog in progs:
        cells = [ratios[n][prog] for n in names]
        table.append([
            prog,
            *[f"{c['forward_s'] * 1e3:.3f}" if "ratio" in c else c["error"] for c in cells],
            *[f"{c['backward_s'] * 1e3:.3f}" if "ratio" in c else "-" for c in cells],
            *[f"{c['ratio']:.2f}" if "ratio" in c else "-" for c in cells],
        ])  # fmt: skip
    harness.print_table(header, table)

    print("\ngradient accuracy against float64 finite differences (d sum(out) / d k)")
    header = ["case", "reference", *[f"{n}" for n in names], *[f"{n} verdict" for n in names]]
    table = []
    for i, case in enumerate(rows_acc[names[0]]):
        table.append([
            case["case"], f"{case['d_k_reference']:.6g}",
            *[f"{rows_acc[n][i]['d_k']:.6g}" for n in names],
            *[rows_acc[n][i]["verdict"] for n in names],
        ])  # fmt: skip
    harness.print_table(header, table)

    data = {"machine": harness.machine(), "device": args.device, "quick": args.quick,
            "ratios": ratios, "accuracy": rows_acc}  # fmt: skip
    path = args.json or RESULTS / f"autodiff-{time.strftime('%Y%m%d-%H%M%S')}.json"
    print()
    harness.save_json(data, path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
