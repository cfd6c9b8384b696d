"""Random numbers: Warp's PCG hash stream, written in kdsl.

The generator is the PCG hash of Jarzynski and Olano ("Hash Functions for GPU
Rendering", JCGT 2020) applied to a 32-bit state: each draw replaces ``state``
with ``pcg(state)`` and derives its value from the new state. ``rand_init``
hashes a seed (and an offset, usually the thread index) into a first state. The
streams are bit-identical to Warp 1.19's (``warp/native/rand.h``) for integers
and ``randf``; results that go through ``log``/``cos``/``acos``/``pow`` match to
the last few ulps of the platform's math library. docs/random.md describes the
stream, its period and how to give each thread its own sequence.

Every function that draws takes ``state`` as an in-out parameter
(``kdsl/frontend/inout.py``): ``x = randf(state)`` advances the caller's
``state`` variable, as Warp's ``uint32&`` does.
"""

import kdsl as wp
from kdsl.frontend.inout import inout
from kdsl.frontend.kernel import func
from kdsl.ir.types import F32, ArrayType
from kdsl.stdlib.algorithms import lower_bound
from kdsl.types import float32, int32, uint32, vec2, vec3, vec4

__kdsl_group__ = "random"

__all__ = [
    "poisson", "rand_init", "randf", "randi", "randn", "randu", "sample_cdf",
    "sample_triangle", "sample_unit_cube", "sample_unit_disk", "sample_unit_hemisphere",
    "sample_unit_hemisphere_surface", "sample_unit_ring", "sample_unit_sphere",
    "sample_unit_sphere_surface", "sample_unit_square",
]  # fmt: skip

#: pi as a float32 literal (Warp's M_PI_F).
PI = 3.14159265358979323846
#: Added to ``randf`` in ``randn`` so ``log`` never sees 0 (Warp's RANDN_EPSILON).
RANDN_EPSILON = 5.96e-8
#: ``randf`` maps the top 24 bits of the state to [0, 1) in steps of 2^-24.
INV_2_24 = 1.0 / 16777216.0


@func
def rand_pcg(state: uint32) -> uint32:
    """``rand_pcg(state)``: the PCG hash of a 32-bit word (the generator's step)."""
    b = state * 747796405 + 2891336453
    c = ((b >> ((b >> 28) + 4)) ^ b) * 277803737
    return (c >> 22) ^ c


@func
def rand_init(seed: int32) -> uint32:
    """``rand_init(seed)``: the first generator state for ``seed`` (``pcg(uint32(seed))``)."""
    return rand_pcg(uint32(seed))


@func
def rand_init(seed: int32, offset: int32) -> uint32:  # noqa: F811 - an overload
    """``rand_init(seed, offset)``: the first state of sequence ``offset`` for ``seed``."""
    return rand_pcg(uint32(seed) + rand_pcg(uint32(offset)))


@func
def randi(state: inout(uint32)) -> int32:
    """``randi(state)``: a uniform int32 over its whole range; advances ``state``."""
    state = rand_pcg(state)
    return int32(state)


@func
def randi(state: inout(uint32), low: int32, high: int32) -> int32:  # noqa: F811
    """``randi(state, low, high)``: a uniform int in ``[low, high)`` (modulo reduction)."""
    state = rand_pcg(state)
    # Warp's unsigned arithmetic: state % uint32(high - low) + uint32(low), as int32.
    return int32(state % uint32(high - low) + uint32(low))


@func
def randu(state: inout(uint32)) -> uint32:
    """``randu(state)``: a uniform uint32 over its whole range; advances ``state``."""
    state = rand_pcg(state)
    return state


@func
def randu(state: inout(uint32), low: uint32, high: uint32) -> uint32:  # noqa: F811
    """``randu(state, low, high)``: a uniform uint32 in ``[low, high)`` (modulo reduction)."""
    state = rand_pcg(state)
    return state % (high - low) + low


@func
def randf(state: inout(uint32)) -> float32:
    """``randf(state)``: a uniform float32 in ``[0, 1)``, a multiple of 2^-24."""
    state = rand_pcg(state)
    return float32(state >> 8) * INV_2_24


@func
def randf(state: inout(uint32), low: float32, high: float32) -> float32:  # noqa: F811
    """``randf(state, low, high)``: a uniform float32 in ``[low, high)``: ``(high-low)*u+low``."""
    return (high - low) * randf(state) + low


@func
def randn(state: inout(uint32)) -> float32:
    """``randn(state)``: a standard normal float32 (Box-Muller; two uniform draws)."""
    return wp.sqrt(-2.0 * wp.log(randf(state) + RANDN_EPSILON)) * wp.cos(2.0 * PI * randf(state))


@func
def sample_cdf(state: inout(uint32), cdf: ArrayType(F32, 1)) -> int32:
    """``sample_cdf(state, cdf)``: the first index ``i`` with ``cdf[i] >= randf(state)``."""
    return lower_bound(cdf, randf(state))


@func
def sample_triangle(state: inout(uint32)) -> vec2:
    """``sample_triangle(state)``: uniform barycentric ``(u, v)`` of a point in a triangle."""
    r = wp.sqrt(randf(state))
    u = 1.0 - r
    v = randf(state) * r
    return vec2(u, v)


@func
def sample_unit_ring(state: inout(uint32)) -> vec2:
    """``sample_unit_ring(state)``: a uniform point on the unit circle."""
    theta = randf(state, 0.0, 2.0 * PI)
    return vec2(wp.cos(theta), wp.sin(theta))


@func
def sample_unit_disk(state: inout(uint32)) -> vec2:
    """``sample_unit_disk(state)``: a uniform point in the unit disk."""
    r = wp.sqrt(randf(state))
    theta = randf(state, 0.0, 2.0 * PI)
    return vec2(r * wp.cos(theta), r * wp.sin(theta))


@func
def sample_unit_sphere_surface(state: inout(uint32)) -> vec3:
    """``sample_unit_sphere_surface(state)``: a uniform point on the unit sphere."""
    phi = wp.acos(1.0 - 2.0 * randf(state))
    theta = randf(state, 0.0, 2.0 * PI)
    return vec3(wp.cos(theta) * wp.sin(phi), wp.sin(theta) * wp.sin(phi), wp.cos(phi))


@func
def sample_unit_sphere(state: inout(uint32)) -> vec3:
    """``sample_unit_sphere(state)``: a uniform point in the unit ball."""
    phi = wp.acos(1.0 - 2.0 * randf(state))
    theta = randf(state, 0.0, 2.0 * PI)
    r = wp.pow(randf(state), 1.0 / 3.0)
    return vec3(r * wp.cos(theta) * wp.sin(phi), r * wp.sin(theta) * wp.sin(phi),
                r * wp.cos(phi))  # fmt: skip


@func
def sample_unit_hemisphere_surface(state: inout(uint32)) -> vec3:
    """``sample_unit_hemisphere_surface(state)``: a uniform point on the unit hemisphere z >= 0."""
    phi = wp.acos(1.0 - randf(state))
    theta = randf(state, 0.0, 2.0 * PI)
    return vec3(wp.cos(theta) * wp.sin(phi), wp.sin(theta) * wp.sin(phi), wp.cos(phi))


@func
def sample_unit_hemisphere(state: inout(uint32)) -> vec3:
    """``sample_unit_hemisphere(state)``: a uniform point in the unit half-ball z >= 0."""
    phi = wp.acos(1.0 - randf(state))
    theta = randf(state, 0.0, 2.0 * PI)
    r = wp.pow(randf(state), 1.0 / 3.0)
    return vec3(r * wp.cos(theta) * wp.sin(phi), r * wp.sin(theta) * wp.sin(phi),
                r * wp.cos(phi))  # fmt: skip


@func
def sample_unit_square(state: inout(uint32)) -> vec2:
    """``sample_unit_square(state)``: a uniform point in ``[-0.5, 0.5)^2``."""
    x = randf(state) - 0.5
    y = randf(state) - 0.5
    return vec2(x, y)


@func
def sample_unit_cube(state: inout(uint32)) -> vec3:
    """``sample_unit_cube(state)``: a uniform point in ``[-0.5, 0.5)^3``."""
    x = randf(state) - 0.5
    y = randf(state) - 0.5
    z = randf(state) - 0.5
    return vec3(x, y, z)


@func
def sample_unit_hypercube(state: inout(uint32)) -> vec4:
    """``sample_unit_hypercube(state)``: a uniform point in ``[-0.5, 0.5)^4`` (used by noise)."""
    a = randf(state) - 0.5
    b = randf(state) - 0.5
    c = randf(state) - 0.5
    d = randf(state) - 0.5
    return vec4(a, b, c, d)


@func
def random_loggam(x: float32) -> float32:
    """``random_loggam(x)``: log(Gamma(x)) in float32 (Zhang and Jin's SPECFUN series)."""
    if x == 1.0 or x == 2.0:
        return 0.0
    n = uint32(0)
    if x < 7.0:
        n = uint32(7.0 - x)
    x0 = x + float32(n)
    x2 = (1.0 / x0) * (1.0 / x0)
    # Horner's rule over the Stirling series coefficients a[9] .. a[0].
    gl0 = float32(-1.39243221690590e00)
    gl0 = gl0 * x2 + 1.796443723688307e-01
    gl0 = gl0 * x2 - 2.955065359477124e-02
    gl0 = gl0 * x2 + 6.410256410256410e-03
    gl0 = gl0 * x2 - 1.917526917526918e-03
    gl0 = gl0 * x2 + 8.417508417508418e-04
    gl0 = gl0 * x2 - 5.952380952380952e-04
    gl0 = gl0 * x2 + 7.936507936507937e-04
    gl0 = gl0 * x2 - 2.777777777777778e-03
    gl0 = gl0 * x2 + 8.333333333333333e-02
    gl = gl0 / x0 + 0.5 * 1.8378770664093453 + (x0 - 0.5) * wp.log(x0) - x0
    for _k in range(int32(n)):
        gl = gl - wp.log(x0 - 1.0)
        x0 = x0 - 1.0
    return gl


@func
def random_poisson_mult(state: inout(uint32), lam: float32) -> uint32:
    """``random_poisson_mult(state, lam)``: Poisson by multiplying uniforms (small ``lam``)."""
    enlam = wp.exp(-lam)
    count = uint32(0)
    prod = float32(1.0)
    while True:
        prod = prod * randf(state)
        if not (prod > enlam):
            break
        count = count + 1
    return count


@func
def random_poisson(state: inout(uint32), lam: float32) -> uint32:
    """``random_poisson(state, lam)``: Poisson by Hoermann's transformed rejection (PTRS)."""
    slam = wp.sqrt(lam)
    loglam = wp.log(lam)
    b = 0.931 + 2.53 * slam
    a = -0.059 + 0.02483 * b
    invalpha = 1.1239 + 1.1328 / (b - 3.4)
    vr = 0.9277 - 3.6224 / (b - 2.0)
    k = float32(0.0)
    while True:
        u = randf(state) - 0.5
        v = randf(state)
        us = 0.5 - wp.abs(u)
        # Kept as a float until known non-negative (a negative float -> uint32 is UB in C).
        k = wp.floor((2.0 * a / us + b) * u + lam + 0.43)
        if us >= 0.07 and v <= vr:
            break
        if k < 0.0 or (us < 0.013 and v > us):
            continue
        if wp.log(v) + wp.log(invalpha) - wp.log(a / (us * us) + b) <= (
            -lam + k * loglam - random_loggam(k + 1.0)
        ):
            break
    return uint32(k)


@func
def poisson(state: inout(uint32), lam: float32) -> uint32:
    """``poisson(state, lam)``: a Poisson(``lam``) count; ``lam == 0`` gives 0 and draws nothing."""
    result = uint32(0)
    if lam >= 10.0:
        result = random_poisson(state, lam)
    elif lam != 0.0:
        result = random_poisson_mult(state, lam)
    return result
