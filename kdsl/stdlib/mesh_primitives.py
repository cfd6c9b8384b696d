"""Triangle primitives behind the mesh queries (``kdsl.stdlib.mesh``), in kdsl.

Barycentric coordinates follow Warp's convention: ``(u, v)`` weigh a triangle's first
and second vertices, so the point is ``u * a + v * b + (1 - u - v) * c``. The ray test
is the watertight test of Woop, Benthin and Wald ("Watertight Ray/Triangle
Intersection", JCGT 2013), as Warp's: a ray through an edge or a vertex shared by two
triangles hits at least one of them. Its per-ray set-up (``ray_shear``) is three
vectors, so a triangle costs dot products and no dynamically indexed vector (which
the cpu backend would lower to select chains).
"""

import kdsl as wp
from kdsl.frontend.kernel import func

__kdsl_group__ = "geometry"

#: Helpers of kdsl.stdlib.mesh, not kernel builtins of their own (Warp has none).
__all__: list[str] = []

#: A triangle whose ``|cross(e0, e1)| / (|e0|^2 + |e1|^2 + |e2|^2)`` is below this is a
#: sliver, left out of point queries as Warp leaves it out.
SLIVER_RATIO = 1.0e-6

#: Relative growth of a box's exit distance so rounding never loses a triangle that
#: touches the box's face (``2 * gamma(3)`` of Ize's robust slab test).
BOX_EXIT_SLACK = 1.0000004
#: Relative padding of boxes in the ray/box test (see ``ray_box_entry``).
BOX_PAD = 1.0e-6


@func
def closest_point_to_triangle(a: wp.vec3, b: wp.vec3, c: wp.vec3, p: wp.vec3) -> wp.vec2:
    """Barycentric ``(u, v)`` of the point of triangle ``(a, b, c)`` closest to ``p``
    (Ericson's region test, Warp's ``closest_point_to_triangle``)."""
    ab = b - a
    ac = c - a
    ap = p - a
    d1 = wp.dot(ab, ap)
    d2 = wp.dot(ac, ap)
    if d1 <= 0.0 and d2 <= 0.0:
        return wp.vec2(1.0, 0.0)
    bp = p - b
    d3 = wp.dot(ab, bp)
    d4 = wp.dot(ac, bp)
    if d3 >= 0.0 and d4 <= d3:
        return wp.vec2(0.0, 1.0)
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return wp.vec2(1.0 - v, v)
    cp = p - c
    d5 = wp.dot(ab, cp)
    d6 = wp.dot(ac, cp)
    if d6 >= 0.0 and d5 <= d6:
        return wp.vec2(0.0, 0.0)
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return wp.vec2(1.0 - w, 0.0)
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return wp.vec2(0.0, 1.0 - w)
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return wp.vec2(1.0 - v - w, v)


@func
def furthest_point_to_triangle(a: wp.vec3, b: wp.vec3, c: wp.vec3, p: wp.vec3) -> wp.vec2:
    """Barycentric ``(u, v)`` of the vertex of ``(a, b, c)`` furthest from ``p`` (ties go
    to the later vertex, as Warp's)."""
    da = wp.length_sq(p - a)
    db = wp.length_sq(p - b)
    dc = wp.length_sq(p - c)
    if da > db and da > dc:
        return wp.vec2(1.0, 0.0)
    if db > dc:
        return wp.vec2(0.0, 1.0)
    return wp.vec2(0.0, 0.0)


@func
def is_sliver(a: wp.vec3, b: wp.vec3, c: wp.vec3) -> bool:
    """Whether point queries leave the triangle out: Warp's sliver test, and also a
    triangle of coincident vertices (where Warp's ratio is 0/0)."""
    e0 = b - a
    e1 = c - a
    e2 = c - b
    ratio = wp.length(wp.cross(e0, e1)) / (wp.dot(e0, e0) + wp.dot(e1, e1) + wp.dot(e2, e2))
    return not (ratio >= SLIVER_RATIO)


@func
def triangle_solid_angle(a: wp.vec3, b: wp.vec3, c: wp.vec3, p: wp.vec3) -> float:
    """Signed solid angle of triangle ``(a, b, c)`` seen from ``p`` (Van Oosterom and
    Strackee); positive when ``p`` is behind the triangle's counter-clockwise face."""
    x = a - p
    y = b - p
    z = c - p
    lx = wp.length(x)
    ly = wp.length(y)
    lz = wp.length(z)
    num = wp.dot(x, wp.cross(y, z))
    den = lx * ly * lz + wp.dot(x, y) * lz + wp.dot(x, z) * ly + wp.dot(y, z) * lx
    return 2.0 * wp.atan2(num, den)


@func
def box_distance_sq(lo: wp.vec3, hi: wp.vec3, p: wp.vec3) -> float:
    """Squared distance from ``p`` to the closed box ``[lo, hi]`` (0 inside; NaN for a
    NaN ``p``, so a NaN query prunes every box).

    Written with comparisons rather than ``wp.max``: ``max`` must return the number of
    a number and a NaN (IEEE ``maximumNumber``), which x86 has no instruction for, and
    this test runs at every node a point query visits; ``a if a > b else b`` is one
    ``maxss``."""
    dx = _axis_gap(lo[0], hi[0], p[0])
    dy = _axis_gap(lo[1], hi[1], p[1])
    dz = _axis_gap(lo[2], hi[2], p[2])
    return dx * dx + dy * dy + dz * dz


@func
def _axis_gap(lo: float, hi: float, x: float) -> float:
    """How far ``x`` lies outside ``[lo, hi]`` (0 inside, NaN for a NaN ``x``)."""
    below = lo - x
    above = x - hi
    gap = below if below > above else above
    return gap if gap > 0.0 or gap != gap else 0.0


@func
def box_furthest_distance_sq(lo: wp.vec3, hi: wp.vec3, p: wp.vec3) -> float:
    """Squared distance from ``p`` to the corner of ``[lo, hi]`` furthest from it."""
    d = wp.max(wp.abs(p - lo), wp.abs(p - hi))
    return wp.dot(d, d)


@func
def safe_inverse(x: float) -> float:
    """``1 / x``, with a large finite value for 0 so ``0 * inv`` stays 0 for a ray that
    starts on a slab's face (Warp's ``mesh_query_ray_safe_dir``)."""
    if x == 0.0:
        return 1.0e30
    return 1.0 / x


@func
def lesser(a: float, b: float) -> float:
    """``a < b ? a : b`` (one minss on x86), not ``wp.min``: see ``box_distance_sq``."""
    return a if a < b else b


@func
def greater(a: float, b: float) -> float:
    """``a > b ? a : b`` (one maxss on x86), not ``wp.max``: see ``box_distance_sq``."""
    return a if a > b else b


@func
def ray_box_enter(lo: wp.vec3, hi: wp.vec3, start: wp.vec3, inv: wp.vec3) -> float:
    """Where the ray ``start + t dir`` (``inv`` = componentwise ``1 / dir``, finite)
    enters the closed box ``[lo, hi]``: its entry ``t`` (negative when ``start`` is
    inside), or NaN when it misses the box at every ``t >= 0``. The value orders boxes
    front to back; ``ray_box_entry`` compares it with ``max_t``.

    The box grows by a relative ``BOX_PAD``: a ray with a zero direction component
    (``inv`` = 1e30) that lies exactly in one of the box's face planes would otherwise
    see that slab as a point (``0 * inv = 0`` on both sides) and miss the box. A NaN in
    ``start`` may let the ray enter boxes; the triangle test then finds no hit."""
    pad = (wp.abs(lo) + wp.abs(hi)) * BOX_PAD + wp.vec3(1.0e-20)
    t0 = wp.cw_mul(lo - pad - start, inv)
    t1 = wp.cw_mul(hi + pad - start, inv)
    near = greater(greater(lesser(t0[0], t1[0]), lesser(t0[1], t1[1])), lesser(t0[2], t1[2]))
    far = lesser(lesser(greater(t0[0], t1[0]), greater(t0[1], t1[1])), greater(t0[2], t1[2]))
    far = far * BOX_EXIT_SLACK
    if near <= far and far >= 0.0:
        return near
    return wp.nan


@func
def ray_box_entry(lo: wp.vec3, hi: wp.vec3, start: wp.vec3, inv: wp.vec3, max_t: float) -> bool:
    """Whether the ray ``start + t dir`` meets the closed box ``[lo, hi]`` at some
    ``0 <= t <= max_t`` (see ``ray_box_enter``)."""
    return ray_box_enter(lo, hi, start, inv) <= max_t


@wp.struct
class RayShear:
    """A ray's set-up for the watertight test (``ray_shear``)."""

    ex: wp.vec3
    ey: wp.vec3
    ez: wp.vec3


@func
def ray_shear(dir: wp.vec3) -> RayShear:
    """The watertight test's per-ray set-up ``(ex, ey, ez)``: a triangle
    vertex ``A`` (relative to the ray start) maps to ``(dot(A, ex), dot(A, ey),
    dot(A, ez))``, Woop's sheared and scaled coordinates. The ray's dominant axis
    becomes z; x and y swap when it points down z, to keep the winding."""
    ax = wp.abs(dir[0])
    ay = wp.abs(dir[1])
    az = wp.abs(dir[2])
    # Woop's axis permutation as unit vectors (Warp's max_dim: the first largest).
    ux = wp.vec3(0.0, 1.0, 0.0)
    uy = wp.vec3(0.0, 0.0, 1.0)
    uz = wp.vec3(1.0, 0.0, 0.0)
    dz = dir[0]
    dx = dir[1]
    dy = dir[2]
    if ax < ay or ax < az:
        if ay >= az:
            ux = wp.vec3(0.0, 0.0, 1.0)
            uy = wp.vec3(1.0, 0.0, 0.0)
            uz = wp.vec3(0.0, 1.0, 0.0)
            dz = dir[1]
            dx = dir[2]
            dy = dir[0]
        else:
            ux = wp.vec3(1.0, 0.0, 0.0)
            uy = wp.vec3(0.0, 1.0, 0.0)
            uz = wp.vec3(0.0, 0.0, 1.0)
            dz = dir[2]
            dx = dir[0]
            dy = dir[1]
    if dz < 0.0:
        tmp = ux
        ux = uy
        uy = tmp
        tmpd = dx
        dx = dy
        dy = tmpd
    sx = dx / dz
    sy = dy / dz
    sz = 1.0 / dz
    s = RayShear()
    s.ex = ux - sx * uz
    s.ey = uy - sy * uz
    s.ez = sz * uz
    return s


@func
def intersect_ray_triangle(
    shear: RayShear, start: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3
) -> wp.vec4:
    """The watertight ray/triangle test: ``(t, u, v, det)`` of the hit of the ray
    (``start``, set up by ``ray_shear``) with ``(a, b, c)``, ``t`` in multiples of the
    ray's direction and ``det`` whose sign is Warp's ``sign``; ``t`` is NaN when the ray
    misses (a ray parallel to the face misses it)."""
    ex = shear.ex
    ey = shear.ey
    ez = shear.ez
    pa = a - start
    pb = b - start
    pc = c - start
    ax = wp.dot(pa, ex)
    ay = wp.dot(pa, ey)
    bx = wp.dot(pb, ex)
    by = wp.dot(pb, ey)
    cx = wp.dot(pc, ex)
    cy = wp.dot(pc, ey)
    uu = cx * by - cy * bx
    vv = ax * cy - ay * cx
    ww = bx * ay - by * ax
    if uu == 0.0 or vv == 0.0 or ww == 0.0:
        # On an edge in float32: decide in float64 so neighbours agree (watertightness).
        uu = float(wp.float64(cx) * wp.float64(by) - wp.float64(cy) * wp.float64(bx))
        vv = float(wp.float64(ax) * wp.float64(cy) - wp.float64(ay) * wp.float64(cx))
        ww = float(wp.float64(bx) * wp.float64(ay) - wp.float64(by) * wp.float64(ax))
    miss = wp.vec4(wp.nan, 0.0, 0.0, 0.0)
    if (uu < 0.0 or vv < 0.0 or ww < 0.0) and (uu > 0.0 or vv > 0.0 or ww > 0.0):
        return miss
    det = uu + vv + ww
    if det == 0.0:
        return miss
    tt = uu * wp.dot(pa, ez) + vv * wp.dot(pb, ez) + ww * wp.dot(pc, ez)
    if (det > 0.0 and tt < 0.0) or (det < 0.0 and tt > 0.0):
        return miss
    inv = 1.0 / det
    return wp.vec4(tt * inv, uu * inv, vv * inv, det)
