"""Special functions written in kdsl: ``erfinv`` and ``erfcinv``.

The starting point is M. Giles' single-precision approximation of erfinv
("Approximating the erfinv function", GPU Computing Gems, 2011; relative error
about 1e-7), evaluated on ``w = -log(c * (2 - c))`` where ``c = erfc(x)``, so tiny
``c`` (``erfcinv`` near 0) keeps its precision; below ``c = 4e-7``, past the
polynomial's range, an asymptotic start and Newton steps in float64 take over.
float64 adds Newton steps on ``erf`` (or on ``erfc`` past 0.5, where that residual
is exact) to full precision; float16 computes in float32.

Domain (as Warp): ``erfinv(+-1) = +-inf``, ``erfcinv(0) = inf``, ``erfcinv(2) = -inf``,
NaN outside ``[-1, 1]`` / ``[0, 2]`` and for NaN.
"""

import math

import kdsl as wp
from kdsl import types as kt
from kdsl.frontend.kernel import func

__kdsl_group__ = "math"
__all__ = ["erfcinv", "erfinv"]

_NEWTON_STEPS = {32: 0, 64: 3}
_SQRT_PI = math.sqrt(math.pi)
_HALF_SQRT_PI = _SQRT_PI / 2.0


def _define_for(S, steps):
    """Define the overloads of this module for the float type ``S``."""
    global erfinv, erfcinv

    @func
    def _giles(w: S) -> S:
        # Giles' polynomial in w; the result times erf(x) approximates x.
        if w < S(5.0):
            a = w - S(2.5)
            p = S(2.81022636e-08)
            p = S(3.43273939e-07) + p * a
            p = S(-3.5233877e-06) + p * a
            p = S(-4.39150654e-06) + p * a
            p = S(0.00021858087) + p * a
            p = S(-0.00125372503) + p * a
            p = S(-0.00417768164) + p * a
            p = S(0.246640727) + p * a
            return S(1.50140941) + p * a
        b = wp.sqrt(w) - S(3.0)
        q = S(-0.000200214257)
        q = S(0.000100950558) + q * b
        q = S(0.00134934322) + q * b
        q = S(-0.00367342844) + q * b
        q = S(0.00573950773) + q * b
        q = S(-0.0076224613) + q * b
        q = S(0.00943887047) + q * b
        q = S(1.00167406) + q * b
        return S(2.83297682) + q * b

    @func
    def _inverse(a: S, c: S) -> S:
        # The x >= 0 with erf(x) = a and erfc(x) = c = 1 - a; a is exact when a <= 0.5,
        # c when a > 0.5.
        if c == S(0.0):
            return S(math.inf)
        w = -wp.log(c * (S(2.0) - c))
        if w > S(14.0):  # c below ~4e-7: past the polynomial's range
            return S(_tail(kt.float64(c)))
        x = _giles(w) * a
        for _step in range(steps):
            r = wp.erf(x) - a
            if a > S(0.5):
                r = c - wp.erfc(x)
            dx = r * S(_HALF_SQRT_PI) * wp.exp(x * x)
            if wp.isfinite(dx):
                x = x - dx
        return x

    @func
    def erfinv(x: S) -> S:
        """Inverse error function: the y with ``erf(y) = x``, for x in [-1, 1]."""
        a = wp.abs(x)
        return wp.copysign(_inverse(a, S(1.0) - a), x)

    @func
    def erfcinv(x: S) -> S:
        """Inverse complementary error function: the y with ``erfc(y) = x``, x in [0, 2]."""
        if x > S(1.0):
            c = S(2.0) - x
            return -_inverse(S(1.0) - c, c)
        return _inverse(S(1.0) - x, x)


@func
def _erfc_scaled(x: kt.float64) -> kt.float64:
    # erfc(x) * exp(x^2) for x > 3: directly while erfc is a normal float, else by the
    # asymptotic series 1/(x sqrt(pi)) * (1 - 1/(2x^2) + 3/(4x^4) - 15/(8x^6) + 105/(16x^8)).
    if x < kt.float64(26.0):
        return wp.erfc(x) * wp.exp(x * x)
    u = kt.float64(1.0) / (kt.float64(2.0) * x * x)
    series = kt.float64(1.0) - u * (kt.float64(1.0) - kt.float64(3.0) * u * (
        kt.float64(1.0) - kt.float64(5.0) * u * (kt.float64(1.0) - kt.float64(7.0) * u)))
    return series / (x * kt.float64(_SQRT_PI))


@func
def _tail(c: kt.float64) -> kt.float64:
    # erfcinv(c) for tiny c > 0: the asymptotic x = sqrt(t - log(t) / 2), t = -log(c sqrt(pi)),
    # then Newton steps on log(erfc(x)) - log(c) = -x^2 + log(erfc_scaled(x)) - log(c),
    # which stays finite down to the smallest subnormal c.
    t = -wp.log(c * kt.float64(_SQRT_PI))
    x = wp.sqrt(t - kt.float64(0.5) * wp.log(t))
    log_c = wp.log(c)
    for _step in range(4):
        e = _erfc_scaled(x)
        h = wp.log(e) - x * x - log_c
        x = x + h * e * kt.float64(_HALF_SQRT_PI)
    return x


for _S in (kt.float32, kt.float64):
    _define_for(_S, _NEWTON_STEPS[kt.type_of(_S).bits])


@func
def erfinv(x: kt.float16) -> kt.float16:  # noqa: F811
    """Inverse error function (float16: computed in float32)."""
    return kt.float16(erfinv(kt.float32(x)))


@func
def erfcinv(x: kt.float16) -> kt.float16:  # noqa: F811
    """Inverse complementary error function (float16: computed in float32)."""
    return kt.float16(erfcinv(kt.float32(x)))
