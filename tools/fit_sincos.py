"""Fit the constants of the cpu backend's inline float32 sin/cos (``kdsl/backends/cpu/trig.py``).

    python tools/fit_sincos.py [--check]

Needs ``mpmath``. Prints the Cody-Waite split of pi/2 (a 33-bit ``HI``, then ``LO``), ``2/pi``, the 192 bits of 4/pi and ``2 pi 2^-64`` of the large-argument
reduction, and the near-minimax (Chebyshev) coefficients of

    S(u) = (sin r - r) / r^3,   C(u) = (cos r - 1) / r^2,   u = r^2 <= (pi/4)^2

with four coefficients each, as float64 hex, and the bound on their approximation
error. ``--check`` compares them with the module's and exits 1 on a difference.
"""

from __future__ import annotations

import argparse
import sys


def fit() -> dict[str, tuple[float | int, ...]]:
    """The constants, by name as ``trig`` spells them."""
    import mpmath as mp

    mp.mp.dps = 80  # the 192 bits of 4/pi need 58 digits
    top = (mp.pi / 4 * (1 + mp.mpf("1e-6"))) ** 2  # a little past pi/4: n may be off by ulps

    def s(u):
        r = mp.sqrt(u)
        return mp.mpf(-1) / 6 if u == 0 else (mp.sin(r) - r) / (u * r)

    def c(u):
        return mp.mpf(-1) / 2 if u == 0 else (mp.cos(mp.sqrt(u)) - 1) / u

    out: dict[str, tuple[float | int, ...]] = {}
    for name, f in (("SIN_COEFFS", s), ("COS_COEFFS", c)):
        poly, err = mp.chebyfit(f, [0, top], 4, error=True)
        out[name] = tuple(float(k) for k in reversed(poly))
        # sin r - r (1 + u S) = r^3 (S - fit): relative to sin r, at most u * err.
        print(f"{name}: relative error of sin r / cos r from it <= {float(err * top):.3g}")

    def split(v, bits: int):
        step = mp.mpf(2) ** (mp.floor(mp.log(abs(v), 2)) - bits + 1)
        return mp.nint(v / step) * step

    hi = split(mp.pi / 2, 33)
    out["PIO2_HI"], out["PIO2_LO"] = (float(hi),), (float(mp.pi / 2 - hi),)
    out["TWO_OVER_PI"] = (float(2 / mp.pi),)
    out["PI_2_POW_M64"] = (float(2 * mp.pi * mp.mpf(2) ** -64),)
    out["INV_PIO4"] = (int(mp.floor(4 / mp.pi * mp.mpf(2) ** 191)),)
    return out


def main() -> int:
    """Print the constants; with ``--check``, compare them with ``trig``'s."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true")
    args = parser.parse_args()
    found = fit()
    for name, values in found.items():
        print(f"{name} = {', '.join(hex(v) if isinstance(v, int) else v.hex() for v in values)}")
    if not args.check:
        return 0
    from kdsl.backends.cpu import trig

    def as_tuple(v: object) -> tuple:
        return v if isinstance(v, tuple) else (v,)

    bad = [name for name, v in found.items() if as_tuple(getattr(trig, name)) != v]
    for name in bad:
        print(f"differs: {name}", file=sys.stderr)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
