"""The parallel primitives of ``kdsl.utils`` beside the reference they must match.

    python benchmarks/bench_utils.py [--n 4000000] [--reps 7] [--device cpu|cuda:0] [--json PATH]

For each primitive (pair sort of int32 and float32 keys, inclusive scan of int32 and
float32, sum of float32), the median time of kdsl's call and of the same work done
directly: on the CPU by NumPy on one core (``np.argsort(kind="stable")`` plus the
gathers, ``np.cumsum``, ``np.sum``), on a GPU by CuPy (``cupy.argsort`` plus the
gathers, ``cupy.cumsum``, ``cupy.sum``), and by Warp's ``warp.utils`` when warp-lang
is installed. Results go to benchmarks/results/utils.json.
"""

import argparse
import json
import platform
import sys
from pathlib import Path

import numpy as np

import kdsl as wp

sys.path.insert(0, str(Path(__file__).resolve().parent))
from suite.harness import median_seconds


def median_ms(fn, reps: int, sync) -> float:
    """``median_seconds`` in milliseconds."""
    return 1e3 * median_seconds(fn, reps, sync)


RESULTS = Path(__file__).resolve().parent / "results" / "utils.json"




def _workloads(n: int, device: str):
    rng = np.random.default_rng(0)
    ikeys = rng.integers(0, 2**30, n).astype(np.int32)
    fkeys = rng.standard_normal(n).astype(np.float32)
    vals = np.arange(n, dtype=np.int32)
    xp = np if device == "cpu" else __import__("cupy")
    out = {}
    for name, keys in (("sort_pairs int32", ikeys), ("sort_pairs float32", fkeys)):
        k = wp.array(np.concatenate([keys, keys]), device=device)
        v = wp.array(np.concatenate([vals, vals]), device=device)
        dk, dv = xp.asarray(keys), xp.asarray(vals)

        def ref(dk=dk, dv=dv):
            p = xp.argsort(dk, kind="stable") if xp is np else xp.argsort(dk)
            return dk[p], dv[p]

        out[name] = (lambda k=k, v=v: wp.utils.radix_sort_pairs(k, v, n), ref, (keys, vals))
    for name, x in (("scan int32", ikeys % 100), ("scan float32", fkeys)):
        a = wp.array(x, device=device)
        o = wp.empty(n, dtype=a.dtype, device=device)
        dx = xp.asarray(x)
        do = xp.empty_like(dx)
        ref = lambda dx=dx, do=do: xp.cumsum(dx, out=do)  # noqa: E731
        out[name] = (lambda a=a, o=o: wp.utils.array_scan(a, o), ref, (x,))
    a = wp.array(fkeys, device=device)
    dx = xp.asarray(fkeys)
    # Both sides bring the sum back to the host, as array_sum(values) does.
    out["sum float32"] = (lambda a=a: wp.utils.array_sum(a), lambda dx=dx: float(dx.sum()),
                          (fkeys,))  # fmt: skip
    return out


def _warp_calls(n: int, device: str, data: dict):
    try:
        import warp
    except ImportError:
        return {}
    warp.config.quiet = True
    calls = {}
    for name, (_, _, arrays) in data.items():
        if name.startswith("sort_pairs"):
            keys, vals = arrays
            k = warp.array(np.concatenate([keys, keys]), device=device)
            v = warp.array(np.concatenate([vals, vals]), device=device)
            calls[name] = lambda k=k, v=v: warp.utils.radix_sort_pairs(k, v, n)
        elif name.startswith("scan"):
            a = warp.array(arrays[0], device=device)
            o = warp.empty_like(a)
            calls[name] = lambda a=a, o=o: warp.utils.array_scan(a, o)
        else:
            a = warp.array(arrays[0], device=device)
            calls[name] = lambda a=a: warp.utils.array_sum(a)
    return calls


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--n", type=int, default=4_000_000)
    p.add_argument("--reps", type=int, default=7)
    p.add_argument("--device", default="cpu")
    p.add_argument("--json", type=Path, default=RESULTS)
    args = p.parse_args()
    if args.device == "cpu":
        sync = lambda: None  # noqa: E731
    else:
        import cupy

        sync = cupy.cuda.Device().synchronize
    data = _workloads(args.n, args.device)
    warp_calls = _warp_calls(args.n, args.device, data)
    ref_name = "NumPy (1 core)" if args.device == "cpu" else "CuPy"
    rows = []
    print(f"n = {args.n:,} on {args.device} ({platform.processor() or platform.machine()}, "
          f"{wp.utils.buffers.host_threads()} host threads)")  # fmt: skip
    print(f"{'primitive':<20} {'kdsl ms':>9} {ref_name + ' ms':>16} {'Warp ms':>9}")
    for name, (ours, ref, _) in data.items():
        row = {"primitive": name, "kdsl_ms": median_ms(ours, args.reps, sync),
               "reference_ms": median_ms(ref, args.reps, sync)}  # fmt: skip
        if name in warp_calls:
            row["warp_ms"] = median_ms(warp_calls[name], args.reps, sync)
        rows.append(row)
        warp_ms = f"{row['warp_ms']:9.2f}" if "warp_ms" in row else f"{'-':>9}"
        print(f"{name:<20} {row['kdsl_ms']:9.2f} {row['reference_ms']:16.2f} {warp_ms}")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"n": args.n, "device": args.device, "reference": ref_name,
                                     "rows": rows}, indent=2))  # fmt: skip
    print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
