"""Warp's mathematical constants: ``kdsl.pi``, ``kdsl.tau``, ``kdsl.e``...

Each is a plain Python ``float`` (``kdsl.pi`` is ``math.pi``), in a lower-case and an
upper-case spelling, as in Warp 1.19. In Python scope they are floats; a kernel or
``@kdsl.func`` reads one as any captured Python float: a weak literal, float32 on its
own (``x = wp.pi`` is a float32) and taking the other operand's type in arithmetic
(``d * wp.pi`` with a float64 ``d`` is float64), so ``wp.float64(wp.pi)`` is pi
rounded once, to float64.
"""

from __future__ import annotations

import math

#: The constants by lower-case name (each also has an upper-case spelling).
CONSTANTS: dict[str, float] = {
    "pi": math.pi,
    "tau": math.tau,
    "e": math.e,
    "inf": math.inf,
    "nan": math.nan,
    "half_pi": math.pi / 2.0,
    "ln2": math.log(2.0),
    "ln10": math.log(10.0),
    "log2e": math.log2(math.e),
    "log10e": math.log10(math.e),
    "phi": (1.0 + math.sqrt(5.0)) / 2.0,
}

pi = PI = CONSTANTS["pi"]
tau = TAU = CONSTANTS["tau"]
e = E = CONSTANTS["e"]
inf = INF = CONSTANTS["inf"]
nan = NAN = CONSTANTS["nan"]
half_pi = HALF_PI = CONSTANTS["half_pi"]
ln2 = LN2 = CONSTANTS["ln2"]
ln10 = LN10 = CONSTANTS["ln10"]
log2e = LOG2E = CONSTANTS["log2e"]
log10e = LOG10E = CONSTANTS["log10e"]
phi = PHI = CONSTANTS["phi"]

__all__ = sorted([*CONSTANTS, *(name.upper() for name in CONSTANTS)])
