"""kdsl standard library: quaternions (Warp's ``quat_*`` functions), written in kdsl.

Quaternions are stored ``(x, y, z, w)``: ``x, y, z`` the vector part, ``w`` the
scalar part, as in Warp. Every function has one overload per float dtype (see
``float_overloads.py``); formulas and edge behaviour follow Warp 1.19, and
docs/semantics.md lists where kdsl differs (NaN propagation in ``normalize``).

The quaternion product (``q1 * q2``, ``mul(q1, q2)``) and the normalization of a
quaternion (``normalize(q)``) are reached through the operators and the
``normalize`` builtin; the frontend calls ``quat_multiply`` and
``quat_normalize`` here for them.
"""

import math

import kdsl as wp
from kdsl.frontend.kernel import func
from kdsl.stdlib.float_overloads import define_float_overloads, functions_in
from kdsl.types import matrix, quaternion, vector

__kdsl_group__ = "quaternion"

_PI = math.pi
_HALF_PI = 0.5 * math.pi


def _quat_functions(S: type) -> dict:
    Q = quaternion(S)
    V3 = vector(3, S)
    M33 = matrix((3, 3), S)
    M44 = matrix((4, 4), S)

    @func
    def quat_multiply(a: Q, b: Q) -> Q:
        """The quaternion product ``a * b`` (applies ``b``'s rotation, then ``a``'s)."""
        return Q(
            a[3] * b[0] + b[3] * a[0] + a[1] * b[2] - b[1] * a[2],
            a[3] * b[1] + b[3] * a[1] + a[2] * b[0] - b[2] * a[0],
            a[3] * b[2] + b[3] * a[2] + a[0] * b[1] - b[0] * a[1],
            a[3] * b[3] - a[0] * b[0] - a[1] * b[1] - a[2] * b[2],
        )

    @func
    def quat_normalize(q: Q) -> Q:
        """``q`` scaled to unit length; the zero quaternion gives the identity (0, 0, 0, 1)."""
        n = wp.length(q)
        if n == S(0.0):
            return Q(S(0.0), S(0.0), S(0.0), S(1.0))
        return q * (S(1.0) / n)

    @func
    def quat_inverse(q: Q) -> Q:
        """The conjugate ``(-x, -y, -z, w)`` of ``q``: its inverse when ``q`` has unit length."""
        return Q(-q[0], -q[1], -q[2], q[3])

    @func
    def quat_from_axis_angle(axis: V3, angle: S) -> Q:
        """The rotation of ``angle`` radians about ``axis`` (unit length, not normalized here)."""
        half = angle * S(0.5)
        v = axis * wp.sin(half)
        return Q(v[0], v[1], v[2], wp.cos(half))

    @func
    def quat_to_axis_angle(q: Q) -> tuple:
        """``(axis, angle)`` of rotation ``q``: angle in [0, pi], axis zero when angle is 0."""
        v = V3(q[0], q[1], q[2])
        axis = wp.normalize(v)
        if q[3] < S(0.0):
            axis = -axis
        return axis, S(2.0) * wp.atan2(wp.length(v), abs(q[3]))

    @func
    def quat_rpy(roll: S, pitch: S, yaw: S) -> Q:
        """The rotation by ``roll``, ``pitch``, ``yaw`` about the fixed x, y, z axes, in order."""
        cy = wp.cos(yaw * S(0.5))
        sy = wp.sin(yaw * S(0.5))
        cr = wp.cos(roll * S(0.5))
        sr = wp.sin(roll * S(0.5))
        cp = wp.cos(pitch * S(0.5))
        sp = wp.sin(pitch * S(0.5))
        return Q(
            cy * sr * cp - sy * cr * sp,
            cy * cr * sp + sy * sr * cp,
            sy * cr * cp - cy * sr * sp,
            cy * cr * cp + sy * sr * sp,
        )

    @func
    def quat_to_rpy(q: Q) -> V3:
        """``(roll, pitch, yaw)`` of unit ``q``, the inverse of ``quat_rpy`` away from gimbal lock."""
        x = q[0]
        y = q[1]
        z = q[2]
        w = q[3]
        roll = wp.atan2(S(2.0) * (w * x + y * z), S(1.0) - S(2.0) * (x * x + y * y))
        sp = min(max(S(2.0) * (w * y - z * x), S(-1.0)), S(1.0))
        pitch = wp.asin(sp)
        yaw = wp.atan2(S(2.0) * (w * z + x * y), S(1.0) - S(2.0) * (y * y + z * z))
        return V3(roll, pitch, yaw)

    @func
    def _axis_quat(axis: int, half: S) -> Q:
        """The rotation of ``2 * half`` radians about coordinate axis 0, 1 or 2."""
        s = wp.sin(half)
        c = wp.cos(half)
        if axis == 0:
            return Q(s, S(0.0), S(0.0), c)
        if axis == 1:
            return Q(S(0.0), s, S(0.0), c)
        return Q(S(0.0), S(0.0), s, c)

    @func
    def quat_from_euler(e: V3, i: int, j: int, k: int) -> Q:
        """The rotation by angles ``e`` (indexed by axis) about fixed axes ``i``, ``j``, ``k``."""
        qi = _axis_quat(i, S(0.5) * e[i])
        qj = _axis_quat(j, S(0.5) * e[j])
        qk = _axis_quat(k, S(0.5) * e[k])
        return quat_multiply(qk, quat_multiply(qj, qi))

    @func
    def _pick(idx: int, a: S, b: S, c: S) -> S:
        """``a``, ``b`` or ``c`` for ``idx`` 1, 2 or 3 (anything else gives ``a``)."""
        if idx == 2:
            return b
        if idx == 3:
            return c
        return a

    @func
    def quat_to_euler(q: Q, i: int, j: int, k: int) -> V3:
        """Angles about fixed axes ``i``, ``j``, ``k`` of ``q``: the inverse of ``quat_from_euler``."""
        # The derivation is for scalar-first quaternions (w, x, y, z) and axes 1..3.
        q0 = q[3]
        q1 = q[0]
        q2 = q[1]
        q3 = q[2]
        i = i + 1
        j = j + 1
        k = k + 1
        not_proper = True
        if i == k:
            not_proper = False
            k = 6 - i - j
        e = S((i - j) * (j - k) * (k - i)) * S(0.5)  # the Levi-Civita symbol of (i, j, k)
        a = q0
        b = _pick(i, q1, q2, q3)
        c = _pick(j, q1, q2, q3)
        d = _pick(k, q1, q2, q3) * e
        if not_proper:
            a = a - _pick(j, q1, q2, q3)
            b = b + _pick(k, q1, q2, q3) * e
            c = c + q0
            d = d - _pick(i, q1, q2, q3)
        n2 = a * a + b * b + c * c + d * d
        t2 = wp.acos(min(max(S(2.0) * (a * a + b * b) / n2 - S(1.0), S(-1.0)), S(1.0)))
        tp = wp.atan2(b, a)
        tm = wp.atan2(d, c)
        t1 = S(0.0)
        t3 = S(0.0)
        if abs(t2) < S(1.0e-6):
            t3 = S(2.0) * tp - t1
        elif abs(t2 - S(_PI)) < S(1.0e-6):
            t3 = S(2.0) * tm + t1
        else:
            t1 = tp - tm
            t3 = tp + tm
        if not_proper:
            t2 = t2 - S(_HALF_PI)
            t3 = t3 * e
        out = V3(S(0.0), S(0.0), S(0.0))
        out[i - 1] = t1
        out[k - 1] = t3
        out[j - 1] = t2
        return out

    @func
    def quat_rotate(q: Q, v: V3) -> V3:
        """``v`` rotated by unit quaternion ``q`` (``quat_to_matrix(q) @ v``)."""
        u = V3(q[0], q[1], q[2])
        c = S(2.0) * q[3] * q[3] - S(1.0)
        d = S(2.0) * wp.dot(u, v)
        return v * c + u * d + wp.cross(u, v) * (q[3] * S(2.0))

    @func
    def quat_rotate_inv(q: Q, v: V3) -> V3:
        """``v`` rotated by the inverse of unit quaternion ``q``."""
        u = V3(q[0], q[1], q[2])
        c = S(2.0) * q[3] * q[3] - S(1.0)
        d = S(2.0) * wp.dot(u, v)
        return v * c + u * d - wp.cross(u, v) * (q[3] * S(2.0))

    @func
    def quat_slerp(a: Q, b: Q, t: S) -> Q:
        """Spherical interpolation from ``a`` (t=0) to ``b`` (t=1) along the shortest arc."""
        axis, angle = quat_to_axis_angle(quat_multiply(quat_inverse(a), b))
        return quat_multiply(a, quat_from_axis_angle(axis, t * angle))

    @func
    def quat_to_matrix(q: Q) -> M33:
        """The 3x3 rotation matrix of unit quaternion ``q`` (rotates column vectors)."""
        c0 = quat_rotate(q, V3(S(1.0), S(0.0), S(0.0)))
        c1 = quat_rotate(q, V3(S(0.0), S(1.0), S(0.0)))
        c2 = quat_rotate(q, V3(S(0.0), S(0.0), S(1.0)))
        return M33(c0[0], c1[0], c2[0], c0[1], c1[1], c2[1], c0[2], c1[2], c2[2])

    @func
    def _quat_from_rows(r0: V3, r1: V3, r2: V3) -> Q:
        """The unit quaternion of the rotation matrix with rows ``r0``, ``r1``, ``r2``."""
        # Shepperd's method: divide by the largest of 4w^2, 4x^2, 4y^2, 4z^2.
        tr = r0[0] + r1[1] + r2[2]
        x = S(0.0)
        y = S(0.0)
        z = S(0.0)
        w = S(0.0)
        if tr >= S(0.0):
            h = wp.sqrt(tr + S(1.0))
            w = S(0.5) * h
            h = S(0.5) / h
            x = (r2[1] - r1[2]) * h
            y = (r0[2] - r2[0]) * h
            z = (r1[0] - r0[1]) * h
        else:
            big = 0
            if r1[1] > r0[0]:
                big = 1
            if big == 0 and r2[2] > r0[0]:
                big = 2
            if big == 1 and r2[2] > r1[1]:
                big = 2
            if big == 0:
                h = wp.sqrt(r0[0] - (r1[1] + r2[2]) + S(1.0))
                x = S(0.5) * h
                h = S(0.5) / h
                y = (r0[1] + r1[0]) * h
                z = (r2[0] + r0[2]) * h
                w = (r2[1] - r1[2]) * h
            elif big == 1:
                h = wp.sqrt(r1[1] - (r2[2] + r0[0]) + S(1.0))
                y = S(0.5) * h
                h = S(0.5) / h
                z = (r1[2] + r2[1]) * h
                x = (r0[1] + r1[0]) * h
                w = (r0[2] - r2[0]) * h
            else:
                h = wp.sqrt(r2[2] - (r0[0] + r1[1]) + S(1.0))
                z = S(0.5) * h
                h = S(0.5) / h
                x = (r2[0] + r0[2]) * h
                y = (r1[2] + r2[1]) * h
                w = (r1[0] - r0[1]) * h
        return quat_normalize(Q(x, y, z, w))

    @func
    def quat_from_matrix(m: M33) -> Q:
        """The unit quaternion of rotation matrix ``m`` (orthonormal, determinant +1)."""
        return _quat_from_rows(m[0], m[1], m[2])

    @func
    def quat_from_matrix(m: M44) -> Q:  # noqa: F811 - the 4x4 overload
        """The unit quaternion of the rotation in the upper-left 3x3 block of ``m``."""
        return _quat_from_rows(V3(m[0, 0], m[0, 1], m[0, 2]), V3(m[1, 0], m[1, 1], m[1, 2]),
                               V3(m[2, 0], m[2, 1], m[2, 2]))  # fmt: skip

    @func
    def quat_twist(axis: V3, q: Q) -> Q:
        """The twist of ``q`` about unit ``axis`` (swing-twist decomposition), normalized."""
        a = axis * wp.dot(V3(q[0], q[1], q[2]), axis)
        return quat_normalize(Q(a[0], a[1], a[2], q[3]))

    @func
    def quat_twist_angle(axis: V3, q: Q) -> S:
        """The unsigned twist angle of ``q`` about unit ``axis``: ``2 atan2(|q.xyz . axis|, w)``."""
        return S(2.0) * wp.atan2(abs(wp.dot(axis, V3(q[0], q[1], q[2]))), q[3])

    @func
    def quat_twist_angle_signed(axis: V3, q: Q) -> S:
        """The signed twist angle of ``q`` about unit ``axis``: ``2 atan2(q.xyz . axis, w)``."""
        return S(2.0) * wp.atan2(wp.dot(axis, V3(q[0], q[1], q[2])), q[3])

    @func
    def quat_between_vectors(a: V3, b: V3) -> Q:
        """The shortest-arc rotation taking the direction of ``a`` onto that of ``b`` (any
        nonzero lengths). Opposite directions are not handled (as in Warp): use
        ``quat_from_axis_angle`` with a perpendicular axis and pi there."""
        an = wp.normalize(a)
        bn = wp.normalize(b)
        c = wp.cross(an, bn)
        return quat_normalize(Q(c[0], c[1], c[2], S(1.0) + wp.dot(an, bn)))

    return functions_in(locals())


_FUNCTIONS = define_float_overloads(_quat_functions)
globals().update(_FUNCTIONS)

#: Functions the frontend calls for ``q1 * q2`` and ``normalize(q)``: not Warp names, not exported.
FRONTEND_HOOKS = ("quat_multiply", "quat_normalize")

__all__ = sorted(n for n in _FUNCTIONS if not n.startswith("_") and n not in FRONTEND_HOOKS)
