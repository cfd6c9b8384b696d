"""kdsl standard library: Warp's search and edge/triangle query functions, in kdsl.

- ``lower_bound(arr, value)`` / ``lower_bound(arr, begin, end, value)``: binary search
  of a sorted 1-d array, one overload per scalar dtype. As Warp's, it returns the
  first index in ``[begin, end)`` whose element is ``>= value``, except that when
  every element is smaller it returns ``end - 1`` (Warp searches ``[begin, end - 1]``),
  and an empty range returns ``begin``.
- ``closest_point_edge_edge(p1, q1, p2, q2, epsilon)``: the closest points of two
  segments as ``vec3(s, t, d)``, Warp 1.19's algorithm (degenerate edges of squared
  length ``<= epsilon`` are points; parallel edges take ``s = 0``).
- ``intersect_tri_tri(v0, v1, v2, u0, u1, u2)``: 1 if two triangles intersect, else
  0. kdsl uses the separating-axis test (both normals, the nine edge-edge cross
  products and each edge's in-plane normal, so coplanar triangles are handled);
  Warp uses Moeller's interval test. The two agree except within rounding of a
  touching or near-degenerate configuration.

The geometry functions have float32 and float64 overloads (Warp's ``vec3``/``vec3d``).
"""

import kdsl as wp
from kdsl.frontend.kernel import func
from kdsl.stdlib import doc_group
from kdsl.stdlib.float_overloads import functions_in
from kdsl.types import (
    float16,
    float32,
    float64,
    int8,
    int16,
    int32,
    int64,
    uint8,
    uint16,
    uint32,
    uint64,
    vector,
)

__kdsl_group__ = "utility"

#: The element types ``lower_bound`` searches (Warp's ``Scalar``).
SEARCH_DTYPES: tuple[type, ...] = (
    float32, float64, float16, int32, int64, int8, int16, uint8, uint16, uint32, uint64,
)  # fmt: skip


def _search_functions(S: type) -> dict:
    A = wp.array(dtype=S)

    @func
    def lower_bound(arr: A, arr_begin: int, arr_end: int, value: S) -> int:
        """The first index in ``[arr_begin, arr_end)`` of sorted ``arr`` whose element is
        ``>= value``; ``arr_end - 1`` if there is none (as Warp)."""
        lower = arr_begin
        upper = arr_end - 1
        while lower < upper:
            mid = lower + (upper - lower) // 2
            if arr[mid] < value:
                lower = mid + 1
            else:
                upper = mid
        return lower

    @func
    def lower_bound(arr: A, value: S) -> int:  # noqa: F811 - the 2-argument overload
        """``lower_bound(arr, 0, arr.shape[0], value)``."""
        return lower_bound(arr, 0, arr.shape[0], value)

    return functions_in(locals())


def _segment_functions(S: type) -> dict:
    V3 = vector(3, S)

    @doc_group("geometry")
    @func
    def closest_point_edge_edge(p1: V3, q1: V3, p2: V3, q2: V3, epsilon: S) -> V3:
        """Closest points of segments ``[p1, q1]`` and ``[p2, q2]``: ``vec3(s, t, d)`` with the
        points ``p1 + s (q1 - p1)``, ``p2 + t (q2 - p2)`` and their distance ``d``."""
        d1 = q1 - p1
        d2 = q2 - p2
        r = p1 - p2
        a = wp.dot(d1, d1)
        e = wp.dot(d2, d2)
        f = wp.dot(d2, r)
        s = S(0.0)
        t = S(0.0)
        degen1 = a <= epsilon
        degen2 = e <= epsilon
        if degen1 and degen2:
            s = S(0.0)
        elif degen1:
            t = wp.clamp(f / e, S(0.0), S(1.0))
        elif degen2:
            s = wp.clamp(-wp.dot(d1, r) / a, S(0.0), S(1.0))
        else:
            c = wp.dot(d1, r)
            b = wp.dot(d1, d2)
            denom = a * e - b * b
            s_init = S(0.0)
            if denom > S(0.0):
                s_init = wp.clamp((b * f - c * e) / denom, S(0.0), S(1.0))
            t_init = (b * s_init + f) / e
            if t_init < S(0.0):
                s = wp.clamp(-c / a, S(0.0), S(1.0))
            elif t_init > S(1.0):
                s = wp.clamp((b - c) / a, S(0.0), S(1.0))
                t = S(1.0)
            else:
                s = s_init
                t = t_init
        c1 = p1 + d1 * s
        c2 = p2 + d2 * t
        return V3(s, t, wp.length(c2 - c1))

    @func
    def _separated_on(
        axis: V3, v0: V3, v1: V3, v2: V3, u0: V3, u1: V3, u2: V3
    ) -> bool:  # fmt: skip
        """Whether the projections of the triangles on ``axis`` are disjoint."""
        a0 = wp.dot(axis, v0)
        a1 = wp.dot(axis, v1)
        a2 = wp.dot(axis, v2)
        b0 = wp.dot(axis, u0)
        b1 = wp.dot(axis, u1)
        b2 = wp.dot(axis, u2)
        return wp.max(a0, wp.max(a1, a2)) < wp.min(b0, wp.min(b1, b2)) or wp.max(
            b0, wp.max(b1, b2)
        ) < wp.min(a0, wp.min(a1, a2))

    @doc_group("geometry")
    @func
    def intersect_tri_tri(v0: V3, v1: V3, v2: V3, u0: V3, u1: V3, u2: V3) -> int:
        """1 if triangles ``(v0, v1, v2)`` and ``(u0, u1, u2)`` intersect (touching or
        overlapping in a common plane counts), else 0."""
        ev = wp.matrix_from_rows(v1 - v0, v2 - v1, v0 - v2)
        eu = wp.matrix_from_rows(u1 - u0, u2 - u1, u0 - u2)
        nv = wp.cross(ev[0], ev[1])
        nu = wp.cross(eu[0], eu[1])
        hit = 1
        if _separated_on(nv, v0, v1, v2, u0, u1, u2) or _separated_on(nu, v0, v1, v2, u0, u1, u2):
            hit = 0
        for i in range(3):
            if hit == 1:
                in_plane_v = _separated_on(wp.cross(nv, ev[i]), v0, v1, v2, u0, u1, u2)
                if in_plane_v or _separated_on(wp.cross(nu, eu[i]), v0, v1, v2, u0, u1, u2):
                    hit = 0
                else:
                    for j in range(3):
                        if _separated_on(wp.cross(ev[i], eu[j]), v0, v1, v2, u0, u1, u2):
                            hit = 0
        return hit

    return functions_in(locals())


_FUNCTIONS: dict = {}
for _dtype in SEARCH_DTYPES:
    _FUNCTIONS.update(_search_functions(_dtype))
for _dtype in (float32, float64):
    _FUNCTIONS.update(_segment_functions(_dtype))
_FUNCTIONS.pop("_separated_on")
globals().update(_FUNCTIONS)

__all__ = sorted(_FUNCTIONS)
