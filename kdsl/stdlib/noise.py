"""Perlin noise, periodic noise and curl noise: Warp's ``noise.h``, written in kdsl.

A lattice point ``(ix, iy, ...)`` gets a pseudo-random unit gradient by hashing
its integer coordinates with large primes into a generator state and drawing a
point of the unit square/cube/hypercube from it (``random.py``). A sample is the
smootherstep interpolation (``6t^5 - 15t^4 + 10t^3``) of the dot products of
the corner gradients with the offsets to the corners. The corner-value and
gradient formulas follow Warp's operation order, so values match Warp's bit for
bit up to the ulps of ``sqrt`` in the gradient normalization (which is exact).

``state`` selects the field and is never advanced. The gradient of ``noise`` for
autodiff comes from differentiating this code (``floor`` has zero derivative).
"""

import kdsl as wp
from kdsl.frontend.kernel import func
from kdsl.stdlib.random import (
    rand_pcg,
    randf,
    sample_unit_cube,
    sample_unit_hypercube,
    sample_unit_square,
)
from kdsl.types import float32, int32, uint32, vec2, vec3, vec4

__kdsl_group__ = "random"

__all__ = ["curlnoise", "noise", "pnoise"]

# Primes that spread lattice coordinates over the 32-bit state (Warp's p1..p4).
P1 = 73856093
P2 = 19349663
P3 = 53471161
P4 = 10000019
# Offsets that make the second and third potential of 3-D curl noise independent.
CURL_OFFSET_2 = 10019689
CURL_OFFSET_3 = 13112221


@func
def smootherstep(t: float32) -> float32:
    """``smootherstep(t)``: ``6t^5 - 15t^4 + 10t^3``, Perlin's fade curve."""
    return t * t * t * (t * (t * 6.0 - 15.0) + 10.0)


@func
def smootherstep_gradient(t: float32) -> float32:
    """``smootherstep_gradient(t)``: the derivative ``30t^2 (t - 1)^2`` of ``smootherstep``."""
    return 30.0 * t * t * (t * (t - 2.0) + 1.0)


@func
def interpolate(a0: float32, a1: float32, t: float32) -> float32:
    """``interpolate(a0, a1, t)``: ``a0`` blended into ``a1`` by ``smootherstep(t)``."""
    return (a1 - a0) * smootherstep(t) + a0


def _define_interpolate_gradient(V):
    """Define ``interpolate_gradient`` for gradients of type ``V``."""
    global interpolate_gradient

    @func
    def interpolate_gradient(a0: float32, a1: float32, t: float32, d_a0: V, d_a1: V,
                             d_t: V) -> V:  # fmt: skip
        """``interpolate_gradient(...)``: the gradient of ``interpolate`` from its inputs' gradients."""
        return (d_a1 - d_a0) * smootherstep(t) + (a1 - a0) * smootherstep_gradient(t) * d_t + d_a0


for _V in (vec2, vec3, vec4):
    _define_interpolate_gradient(_V)


@func
def normalized(v: vec2) -> vec2:
    """``normalized(v)``: Warp's ``normalize``: each component divided by the length."""
    n = wp.sqrt(v[0] * v[0] + v[1] * v[1])
    out = vec2()
    if n > 0.0:
        out = vec2(v[0] / n, v[1] / n)
    return out


@func
def normalized(v: vec3) -> vec3:  # noqa: F811
    """``normalized(v)``: Warp's ``normalize`` (3-D)."""
    n = wp.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    out = vec3()
    if n > 0.0:
        out = vec3(v[0] / n, v[1] / n, v[2] / n)
    return out


@func
def normalized(v: vec4) -> vec4:  # noqa: F811
    """``normalized(v)``: Warp's ``normalize`` (4-D)."""
    n = wp.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2] + v[3] * v[3])
    out = vec4()
    if n > 0.0:
        out = vec4(v[0] / n, v[1] / n, v[2] / n, v[3] / n)
    return out


# --- lattice gradients ------------------------------------------------------------
# Python's precedence of ^ below + and * is C's, so these hash exactly as Warp's do.


@func
def random_gradient(state: uint32, ix: int32) -> float32:
    """``random_gradient(state, ix)``: the 1-D lattice gradient at ``ix``, in [-1, 1)."""
    idx = uint32(ix) * P1 + state
    return randf(idx, -1.0, 1.0)


@func
def random_gradient(state: uint32, ix: int32, iy: int32) -> vec2:  # noqa: F811
    """``random_gradient(state, ix, iy)``: the unit 2-D lattice gradient at ``(ix, iy)``."""
    idx = uint32(ix) * P1 ^ uint32(iy) * P2 + state
    return normalized(sample_unit_square(idx))


@func
def random_gradient(state: uint32, ix: int32, iy: int32, iz: int32) -> vec3:  # noqa: F811
    """``random_gradient(state, ix, iy, iz)``: the unit 3-D lattice gradient."""
    idx = uint32(ix) * P1 ^ uint32(iy) * P2 ^ uint32(iz) * P3 + state
    return normalized(sample_unit_cube(idx))


@func
def random_gradient(state: uint32, ix: int32, iy: int32, iz: int32,  # noqa: F811
                    it: int32) -> vec4:  # fmt: skip
    """``random_gradient(state, ix, iy, iz, it)``: the unit 4-D lattice gradient."""
    idx = uint32(ix) * P1 ^ uint32(iy) * P2 ^ uint32(iz) * P3 ^ uint32(it) * P4 + state
    return normalized(sample_unit_hypercube(idx))


# --- interpolation trees: (value, gradient) of one cell ---------------------------
# Each level blends two halves of the cell along one axis, in Warp's order
# (x first, then y, z, t). Callers that need only the value discard the gradient,
# which the optimizer removes after inlining.


@func
def noise_1d(state: uint32, x0: int32, x1: int32, dx: float32) -> float32:
    """``noise_1d(state, x0, x1, dx)``: 1-D Perlin noise of the cell ``[x0, x1]`` at ``dx``."""
    v0 = dx * random_gradient(state, x0)
    v1 = (dx - 1.0) * random_gradient(state, x1)
    return interpolate(v0, v1, dx)


@func
def cell_x(state: uint32, x0: int32, x1: int32, y: int32, dx: float32, oy: float32):
    """``cell_x(...)``: value and gradient of a 2-D cell edge along x at row ``y``."""
    g0 = random_gradient(state, x0, y)
    g1 = random_gradient(state, x1, y)
    v0 = dx * g0[0] + oy * g0[1]
    v1 = (dx - 1.0) * g1[0] + oy * g1[1]
    return interpolate(v0, v1, dx), interpolate_gradient(v0, v1, dx, g0, g1, vec2(1.0, 0.0))


@func
def noise_2d(state: uint32, x0: int32, y0: int32, x1: int32, y1: int32, dx: float32,
             dy: float32):  # fmt: skip
    """``noise_2d(...)``: value and gradient of 2-D Perlin noise in one cell."""
    a, ga = cell_x(state, x0, x1, y0, dx, dy)
    b, gb = cell_x(state, x0, x1, y1, dx, dy - 1.0)
    return interpolate(a, b, dy), interpolate_gradient(a, b, dy, ga, gb, vec2(0.0, 1.0))


@func
def cell_x(state: uint32, x0: int32, x1: int32, y: int32, z: int32, dx: float32,  # noqa: F811
           oy: float32, oz: float32):  # fmt: skip
    """``cell_x(...)``: value and gradient of a 3-D cell edge along x."""
    g0 = random_gradient(state, x0, y, z)
    g1 = random_gradient(state, x1, y, z)
    v0 = dx * g0[0] + oy * g0[1] + oz * g0[2]
    v1 = (dx - 1.0) * g1[0] + oy * g1[1] + oz * g1[2]
    return interpolate(v0, v1, dx), interpolate_gradient(v0, v1, dx, g0, g1,
                                                         vec3(1.0, 0.0, 0.0))  # fmt: skip


@func
def cell_y(state: uint32, x0: int32, x1: int32, y0: int32, y1: int32, z: int32, dx: float32,
           dy: float32, oz: float32):  # fmt: skip
    """``cell_y(...)``: value and gradient of a 3-D cell face at layer ``z``."""
    a, ga = cell_x(state, x0, x1, y0, z, dx, dy, oz)
    b, gb = cell_x(state, x0, x1, y1, z, dx, dy - 1.0, oz)
    return interpolate(a, b, dy), interpolate_gradient(a, b, dy, ga, gb, vec3(0.0, 1.0, 0.0))


@func
def noise_3d(state: uint32, x0: int32, y0: int32, z0: int32, x1: int32, y1: int32, z1: int32,
             dx: float32, dy: float32, dz: float32):  # fmt: skip
    """``noise_3d(...)``: value and gradient of 3-D Perlin noise in one cell."""
    a, ga = cell_y(state, x0, x1, y0, y1, z0, dx, dy, dz)
    b, gb = cell_y(state, x0, x1, y0, y1, z1, dx, dy, dz - 1.0)
    return interpolate(a, b, dz), interpolate_gradient(a, b, dz, ga, gb, vec3(0.0, 0.0, 1.0))


@func
def cell_x(state: uint32, x0: int32, x1: int32, y: int32, z: int32, t: int32,  # noqa: F811
           dx: float32, oy: float32, oz: float32, ot: float32):  # fmt: skip
    """``cell_x(...)``: value and gradient of a 4-D cell edge along x."""
    g0 = random_gradient(state, x0, y, z, t)
    g1 = random_gradient(state, x1, y, z, t)
    v0 = dx * g0[0] + oy * g0[1] + oz * g0[2] + ot * g0[3]
    v1 = (dx - 1.0) * g1[0] + oy * g1[1] + oz * g1[2] + ot * g1[3]
    return interpolate(v0, v1, dx), interpolate_gradient(v0, v1, dx, g0, g1,
                                                         vec4(1.0, 0.0, 0.0, 0.0))  # fmt: skip


@func
def cell_y(state: uint32, x0: int32, x1: int32, y0: int32, y1: int32, z: int32,  # noqa: F811
           t: int32, dx: float32, dy: float32, oz: float32, ot: float32):  # fmt: skip
    """``cell_y(...)``: value and gradient of a 4-D cell face."""
    a, ga = cell_x(state, x0, x1, y0, z, t, dx, dy, oz, ot)
    b, gb = cell_x(state, x0, x1, y1, z, t, dx, dy - 1.0, oz, ot)
    return interpolate(a, b, dy), interpolate_gradient(a, b, dy, ga, gb,
                                                       vec4(0.0, 1.0, 0.0, 0.0))  # fmt: skip


@func
def cell_z(state: uint32, x0: int32, x1: int32, y0: int32, y1: int32, z0: int32, z1: int32,
           t: int32, dx: float32, dy: float32, dz: float32, ot: float32):  # fmt: skip
    """``cell_z(...)``: value and gradient of a 4-D cell volume at time ``t``."""
    a, ga = cell_y(state, x0, x1, y0, y1, z0, t, dx, dy, dz, ot)
    b, gb = cell_y(state, x0, x1, y0, y1, z1, t, dx, dy, dz - 1.0, ot)
    return interpolate(a, b, dz), interpolate_gradient(a, b, dz, ga, gb,
                                                       vec4(0.0, 0.0, 1.0, 0.0))  # fmt: skip


@func
def noise_4d(state: uint32, x0: int32, y0: int32, z0: int32, t0: int32, x1: int32, y1: int32,
             z1: int32, t1: int32, dx: float32, dy: float32, dz: float32, dt: float32):  # fmt: skip
    """``noise_4d(...)``: value and gradient of 4-D Perlin noise in one cell."""
    a, ga = cell_z(state, x0, x1, y0, y1, z0, z1, t0, dx, dy, dz, dt)
    b, gb = cell_z(state, x0, x1, y0, y1, z0, z1, t1, dx, dy, dz, dt - 1.0)
    return interpolate(a, b, dt), interpolate_gradient(a, b, dt, ga, gb,
                                                       vec4(0.0, 0.0, 0.0, 1.0))  # fmt: skip


# --- public noise -----------------------------------------------------------------


@func
def perlin(state: uint32, x: float32):
    """``perlin(state, x)``: value and (unused, zero) gradient of 1-D Perlin noise at ``x``."""
    fx = wp.floor(x)
    x0 = int32(fx)
    return noise_1d(state, x0, x0 + 1, x - fx), float32(0.0)


@func
def perlin(state: uint32, xy: vec2):  # noqa: F811
    """``perlin(state, xy)``: value and gradient of 2-D Perlin noise at ``xy``."""
    f = wp.floor(xy)
    x0 = int32(f[0])
    y0 = int32(f[1])
    return noise_2d(state, x0, y0, x0 + 1, y0 + 1, xy[0] - f[0], xy[1] - f[1])


@func
def perlin(state: uint32, xyz: vec3):  # noqa: F811
    """``perlin(state, xyz)``: value and gradient of 3-D Perlin noise at ``xyz``."""
    f = wp.floor(xyz)
    x0 = int32(f[0])
    y0 = int32(f[1])
    z0 = int32(f[2])
    return noise_3d(state, x0, y0, z0, x0 + 1, y0 + 1, z0 + 1, xyz[0] - f[0], xyz[1] - f[1],
                    xyz[2] - f[2])  # fmt: skip


@func
def perlin(state: uint32, xyzt: vec4):  # noqa: F811
    """``perlin(state, xyzt)``: value and gradient of 4-D Perlin noise at ``xyzt``."""
    f = wp.floor(xyzt)
    x0 = int32(f[0])
    y0 = int32(f[1])
    z0 = int32(f[2])
    t0 = int32(f[3])
    return noise_4d(state, x0, y0, z0, t0, x0 + 1, y0 + 1, z0 + 1, t0 + 1, xyzt[0] - f[0],
                    xyzt[1] - f[1], xyzt[2] - f[2], xyzt[3] - f[3])  # fmt: skip


def _define_noise(V):
    """Define ``noise`` and ``noise_gradient`` for points of type ``V``."""
    global noise, noise_gradient

    @func
    def noise(state: uint32, p: V) -> float32:
        """``noise(state, p)``: Perlin noise at ``p`` (1-D to 4-D); ``state`` picks the field."""
        value, _ = perlin(state, p)
        return value

    @func
    def noise_gradient(state: uint32, p: V) -> V:
        """``noise_gradient(state, p)``: the gradient of ``noise`` at ``p``."""
        _, g = perlin(state, p)
        return g


for _V in (float32, vec2, vec3, vec4):
    _define_noise(_V)


# Periodic noise: lattice coordinates wrap with C's remainder (``%`` on ints), as in
# Warp; negative coordinates therefore give negative cells (Warp leaves them unsupported).


@func
def pnoise(state: uint32, x: float32, px: int32) -> float32:
    """``pnoise(state, x, px)``: 1-D Perlin noise repeating every ``px`` units."""
    fx = wp.floor(x)
    x0 = int32(fx) % px
    return noise_1d(state, x0, (x0 + 1) % px, x - fx)


@func
def pnoise(state: uint32, xy: vec2, px: int32, py: int32) -> float32:  # noqa: F811
    """``pnoise(state, xy, px, py)``: 2-D Perlin noise repeating every ``(px, py)``."""
    f = wp.floor(xy)
    x0 = int32(f[0]) % px
    y0 = int32(f[1]) % py
    value, _ = noise_2d(state, x0, y0, (x0 + 1) % px, (y0 + 1) % py, xy[0] - f[0], xy[1] - f[1])
    return value


@func
def pnoise(state: uint32, xyz: vec3, px: int32, py: int32, pz: int32) -> float32:  # noqa: F811
    """``pnoise(state, xyz, px, py, pz)``: 3-D Perlin noise repeating every ``(px, py, pz)``."""
    f = wp.floor(xyz)
    x0 = int32(f[0]) % px
    y0 = int32(f[1]) % py
    z0 = int32(f[2]) % pz
    value, _ = noise_3d(state, x0, y0, z0, (x0 + 1) % px, (y0 + 1) % py, (z0 + 1) % pz,
                        xyz[0] - f[0], xyz[1] - f[1], xyz[2] - f[2])  # fmt: skip
    return value


@func
def pnoise(state: uint32, xyzt: vec4, px: int32, py: int32, pz: int32,  # noqa: F811
           pt: int32) -> float32:  # fmt: skip
    """``pnoise(state, xyzt, px, py, pz, pt)``: 4-D Perlin noise with a period per axis."""
    f = wp.floor(xyzt)
    x0 = int32(f[0]) % px
    y0 = int32(f[1]) % py
    z0 = int32(f[2]) % pz
    t0 = int32(f[3]) % pt
    value, _ = noise_4d(state, x0, y0, z0, t0, (x0 + 1) % px, (y0 + 1) % py, (z0 + 1) % pz,
                        (t0 + 1) % pt, xyzt[0] - f[0], xyzt[1] - f[1], xyzt[2] - f[2],
                        xyzt[3] - f[3])  # fmt: skip
    return value


# --- curl noise -------------------------------------------------------------------


@func
def next_potential(state: uint32, offset: uint32) -> uint32:
    """``next_potential(state, offset)``: Warp's ``rand_init(state, offset)`` on a uint32 state."""
    return rand_pcg(state + rand_pcg(offset))


def _define_curlnoise(P, R):
    """Define ``curlnoise`` for points of type ``P`` and curls of type ``R``, with Warp's
    defaults (octaves=1, lacunarity=2, gain=0.5) as shorter overloads."""
    global curlnoise

    @func
    def curlnoise(state: uint32, p: P, octaves: uint32, lacunarity: float32, gain: float32) -> R:
        """``curlnoise(state, p, octaves=1, lacunarity=2, gain=0.5)``: divergence-free noise:
        the curl of one potential in 2-D, of three in 3-D (and 3-D over time)."""
        s1 = P()
        s2 = P()
        s3 = P()
        freq = float32(1.0)
        amplitude = float32(1.0)
        for _i in range(int32(octaves)):
            pt = freq * p
            if wp.static(P is vec2):
                s1 = s1 + amplitude * noise_gradient(state, pt)
            else:
                # One gradient per potential; a loop keeps a single copy of the noise code.
                for j in range(3):
                    if j == 1:
                        state = next_potential(state, uint32(CURL_OFFSET_2))
                    elif j == 2:
                        state = next_potential(state, uint32(CURL_OFFSET_3))
                    g = amplitude * noise_gradient(state, pt)
                    if j == 0:
                        s1 = s1 + g
                    elif j == 1:
                        s2 = s2 + g
                    else:
                        s3 = s3 + g
            amplitude = amplitude * gain
            freq = freq * lacunarity
        if wp.static(P is vec2):
            return vec2(-s1[1], s1[0])
        else:
            return vec3(s3[1] - s2[2], s1[2] - s3[0], s2[0] - s1[1])

    @func
    def curlnoise(state: uint32, p: P) -> R:  # noqa: F811 - overloads
        """``curlnoise(state, p)``: one octave of curl noise."""
        return curlnoise(state, p, uint32(1), 2.0, 0.5)

    @func
    def curlnoise(state: uint32, p: P, octaves: uint32) -> R:  # noqa: F811 - overloads
        """``curlnoise(state, p, octaves)``: curl noise, lacunarity 2, gain 0.5."""
        return curlnoise(state, p, octaves, 2.0, 0.5)

    @func
    def curlnoise(state: uint32, p: P, octaves: uint32, lacunarity: float32) -> R:  # noqa: F811 - overloads
        """``curlnoise(state, p, octaves, lacunarity)``: curl noise, gain 0.5."""
        return curlnoise(state, p, octaves, lacunarity, 0.5)


for _P, _R in ((vec2, vec2), (vec3, vec3), (vec4, vec3)):
    _define_curlnoise(_P, _R)
