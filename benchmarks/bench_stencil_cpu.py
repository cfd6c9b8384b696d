"""Jacobi and cloth on the CPU, kdsl and Numba interleaved in one process.

``bench_cpu.py`` times each framework in its own block of samples; on a shared,
busy host the load changes between blocks and the ratio swings. Here every sample
runs one kdsl step and then one Numba step, so both see the same load, and the
table gives the ratio of their minimum and of their median times (Numba / kdsl:
above 1 means kdsl is faster). Results are checked against the float64 references
of ``suite/workloads.py`` first.

    python benchmarks/bench_stencil_cpu.py                  # 2^12 Jacobi, 256^2 cloth
    python benchmarks/bench_stencil_cpu.py --threads 1 --sizes 512,1024,4096
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from suite import harness
from suite import workloads as W


def _check(name: str, got: dict, ins: dict) -> None:
    ref = getattr(W, f"{name}_reference")(ins)
    for key, want in ref.items():
        g = np.asarray(got[key]).reshape(np.shape(want))
        if not np.allclose(g, want, rtol=1e-4, atol=1e-4):
            raise SystemExit(f"{name}: {key} differs from the reference")


def interleaved(name: str, size: int, reps: int) -> dict[str, float]:
    """Min and median ms of kdsl and Numba steps run alternately ``reps`` times."""
    from suite import kdsl_impl as K
    from suite import numba_impl as N

    ins = getattr(W, f"{name}_inputs")(size, np.random.default_rng(0))
    runners = {"kdsl": K.RUNNERS[name](ins), "numba": getattr(N, name)(ins)}
    for r in runners.values():
        for _ in range(3):
            r.step()
        _check(name, r.fetch(), ins)
    times: dict[str, list[float]] = {k: [] for k in runners}
    for _ in range(reps):
        for k, r in runners.items():
            t = time.perf_counter()
            r.step()
            times[k].append((time.perf_counter() - t) * 1e3)
    out = {}
    for k, ts in times.items():
        out[f"{k}_min"], out[f"{k}_median"] = float(np.min(ts)), float(np.median(ts))
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--threads", type=int, default=None, help="threads of both (default: all)")
    p.add_argument("--sizes", default="4096", help="Jacobi grid sizes, comma list")
    p.add_argument("--reps", type=int, default=None, help="samples (default per size)")
    p.add_argument("--json", type=Path, default=None)
    a = p.parse_args()
    try:
        import numba
    except ImportError:
        raise SystemExit("numba is not installed (the bench extra installs it)") from None
    from kdsl.backends.cpu import set_num_threads

    if a.threads:
        numba.set_num_threads(a.threads)
        set_num_threads(a.threads)
    cases = [("jacobi", int(s)) for s in a.sizes.split(",")] + [("cloth", 256)]
    rows, data = [], {}
    for name, size in cases:
        reps = a.reps or max(10, min(400, int(2e8 / size**2)))
        r = interleaved(name, size, reps)
        data[f"{name} {size}"] = r
        rows.append([f"{name} ({size}^2)", f"{r['kdsl_min']:.3g}", f"{r['numba_min']:.3g}",
                     f"{r['numba_min'] / r['kdsl_min']:.2f}x",
                     f"{r['numba_median'] / r['kdsl_median']:.2f}x"])  # fmt: skip
    harness.print_table(
        ["workload", "kdsl min [ms]", "numba min [ms]", "numba/kdsl (min)", "(median)"], rows
    )
    meta = {"threads": a.threads, "machine": harness.machine(), "numba": numba.__version__}
    path = (
        a.json
        or Path(__file__).resolve().parent / "results" / f"stencil-cpu-{int(time.time())}.json"
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"meta": meta, "results": data}, indent=1))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
