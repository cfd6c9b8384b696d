"""kdsl standard library: spatial (6D) algebra (Warp's ``spatial_*`` functions), in kdsl.

A spatial vector is ``(w, v)``: an angular part (components 0 to 2) over a linear
part (3 to 5), as in Warp and Featherstone's notation. A twist is ``(angular
velocity, linear velocity)``, a wrench ``(torque, force)``. Every function has
one overload per float dtype (see ``float_overloads.py``) and follows Warp 1.19.
"""

import kdsl as wp
from kdsl.frontend.kernel import func
from kdsl.stdlib.float_overloads import define_float_overloads, functions_in
from kdsl.stdlib.quat import quat_rotate
from kdsl.stdlib.transform import transform_get_rotation, transform_get_translation
from kdsl.types import matrix, transformation, vector

__kdsl_group__ = "spatial"


def _spatial_functions(S: type) -> dict:
    V3 = vector(3, S)
    SV = vector(6, S)
    M33 = matrix((3, 3), S)
    SM = matrix((6, 6), S)
    T = transformation(S)

    @func
    def spatial_top(svec: SV) -> V3:
        """The angular part of ``svec`` (components 0 to 2)."""
        return V3(svec[0], svec[1], svec[2])

    @func
    def spatial_bottom(svec: SV) -> V3:
        """The linear part of ``svec`` (components 3 to 5)."""
        return V3(svec[3], svec[4], svec[5])

    @func
    def spatial_dot(a: SV, b: SV) -> S:
        """The dot product of two spatial vectors (a wrench dotted with a twist is power)."""
        return wp.dot(a, b)

    @func
    def spatial_cross(a: SV, b: SV) -> SV:
        """The motion cross product of twists: ``(wa x wb, va x wb + wa x vb)``."""
        wa = spatial_top(a)
        wb = spatial_top(b)
        w = wp.cross(wa, wb)
        v = wp.cross(spatial_bottom(a), wb) + wp.cross(wa, spatial_bottom(b))
        return SV(w, v)

    @func
    def spatial_cross_dual(a: SV, b: SV) -> SV:
        """The force cross product of twist ``a`` and wrench ``b``: ``(wa x wb + va x vb, wa x vb)``."""
        wa = spatial_top(a)
        vb = spatial_bottom(b)
        w = wp.cross(wa, spatial_top(b)) + wp.cross(spatial_bottom(a), vb)
        return SV(w, wp.cross(wa, vb))

    @func
    def spatial_adjoint(r: M33, s: M33) -> SM:
        """The 6x6 block matrix ``[[r, 0], [s, r]]`` (with ``s = skew(p) R``, the twist adjoint)."""
        out = SM()
        for i in range(3):
            for j in range(3):
                out[i, j] = r[i, j]
                out[i + 3, j + 3] = r[i, j]
                out[i + 3, j] = s[i, j]
        return out

    @func
    def transform_twist(t: T, x: SV) -> SV:
        """Twist ``x`` moved by transform ``t = (R, p)``: ``(R w, R v + p x R w)``."""
        q = transform_get_rotation(t)
        w = quat_rotate(q, spatial_top(x))
        v = quat_rotate(q, spatial_bottom(x)) + wp.cross(transform_get_translation(t), w)
        return SV(w, v)

    @func
    def transform_wrench(t: T, x: SV) -> SV:
        """Wrench ``x`` moved by transform ``t = (R, p)``: ``(R tau + p x R f, R f)``."""
        q = transform_get_rotation(t)
        f = quat_rotate(q, spatial_bottom(x))
        tau = quat_rotate(q, spatial_top(x)) + wp.cross(transform_get_translation(t), f)
        return SV(tau, f)

    @func
    def velocity_at_point(qd: SV, r: V3) -> V3:
        """The linear velocity at offset ``r`` of a body with twist ``qd``: ``v + w x r``."""
        return spatial_bottom(qd) + wp.cross(spatial_top(qd), r)

    return functions_in(locals())


_FUNCTIONS = define_float_overloads(_spatial_functions)
globals().update(_FUNCTIONS)

__all__ = sorted(_FUNCTIONS)
