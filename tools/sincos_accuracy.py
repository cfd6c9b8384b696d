"""Max error in ulp of a backend's float32 ``sin``/``cos`` against NumPy float64.

    python tools/sincos_accuracy.py [--backend cpu] [--low 0] [--bound 1e4] [--stride 1]
                                    [--chunk 16777216]

Every float32 in ``[low, bound)`` whose bit pattern is a multiple of ``stride`` (1:
every one), both signs, plus special values (+-0, denormals, the fast path's bound,
large arguments, +-inf, NaN), each evaluated by one kdsl kernel and compared with
``np.sin``/``np.cos`` of the float64 value, in float32 ulps at the float64 result
(``kdsl.testing.conformance.ulp_distance``): a correctly rounded result is within 0.5.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

import kdsl as wp
from kdsl.testing.conformance import ulp_distance


@wp.kernel
def _sincos(x: wp.array(dtype=float), s: wp.array(dtype=float), c: wp.array(dtype=float)):
    i = wp.tid()
    s[i] = wp.sin(x[i])
    c[i] = wp.cos(x[i])


#: Special values: signed zeros, denormals, the fast path's edge, large, inf, NaN.
SPECIAL = np.array(
    [0.0, -0.0, 1e-45, -1e-45, 1e-40, 1.1754942e-38, 1.17549435e-38, 1e-30, 1e-8,
     np.pi / 4, np.pi / 2, np.pi, 3 * np.pi / 2, 2 * np.pi, 1e4, 65536.0, 1048575.9,
     1048576.0, 1048577.0, 1e6, 1e7, 16777216.0, 1e10, 1e20, 3e38, 3.4028235e38,
     np.inf, -np.inf, np.nan],
    dtype=np.float32,
)  # fmt: skip


def evaluate(x: np.ndarray, device: str) -> tuple[np.ndarray, np.ndarray]:
    """The kernel's ``(sin x, cos x)`` for the float32 array ``x``."""
    xa = wp.array(x, dtype=float, device=device)
    s = wp.empty(len(x), dtype=float, device=device)
    c = wp.empty(len(x), dtype=float, device=device)
    wp.launch(_sincos, len(x), [xa, s, c], device=device)
    return s.numpy(), c.numpy()


def special_report(device: str) -> list[str]:
    """One line per special value: input, kdsl's sin and cos, and their ulp errors."""
    s, c = evaluate(SPECIAL, device)
    d = SPECIAL.astype(np.float64)
    with np.errstate(invalid="ignore"):
        es, ec = ulp_distance(s, np.sin(d)), ulp_distance(c, np.cos(d))
    return [f"{x!r:>16} sin {a!r:>16} ({u:.3f} ulp)  cos {b!r:>16} ({v:.3f} ulp)"
            for x, a, b, u, v in zip(SPECIAL, s, c, es, ec)]  # fmt: skip


def sweep(
    device: str, low: float, bound: float, stride: int, chunk: int
) -> dict[str, tuple[float, float]]:
    """Max ulp error of sin and cos (and where) over the floats with ``low <= |x| < bound``."""
    bottom, top = (int(np.float32(v).view(np.uint32)) for v in (low, bound))
    worst = {"sin": (0.0, 0.0), "cos": (0.0, 0.0)}
    for start in range(bottom, top, chunk * stride):
        bits = np.arange(start, min(start + chunk * stride, top), stride, dtype=np.uint32)
        x = bits.view(np.float32)
        x = np.concatenate([x, -x])
        s, c = evaluate(x, device)
        d = x.astype(np.float64)
        for name, y, exact in (("sin", s, np.sin(d)), ("cos", c, np.cos(d))):
            err = ulp_distance(y, exact)
            k = int(np.argmax(err))
            if err[k] > worst[name][0]:
                worst[name] = (float(err[k]), float(x[k]))
    return worst


def main() -> int:
    """Print the special values and the sweep's max errors."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--backend", default="cpu", choices=["cpu", "cuda", "interp"])
    parser.add_argument("--low", type=float, default=0.0)
    parser.add_argument("--bound", type=float, default=1e4)
    parser.add_argument("--stride", type=int, default=1)
    parser.add_argument("--chunk", type=int, default=1 << 24)
    args = parser.parse_args()
    device = "cuda:0" if args.backend == "cuda" else args.backend
    for line in special_report(device):
        print(line)
    for name, (err, x) in sweep(device, args.low, args.bound, args.stride, args.chunk).items():
        print(f"{name}: max {err:.4f} ulp at x = {x!r} over {args.low:g} <= |x| < "
              f"{args.bound:g}, stride {args.stride}")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
