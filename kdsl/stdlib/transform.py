"""kdsl standard library: rigid transforms (Warp's ``transform_*`` functions), in kdsl.

A transform is 7 scalars ``(p.x, p.y, p.z, q.x, q.y, q.z, q.w)``: a translation
``p`` and a unit rotation quaternion ``q``; it maps ``x`` to ``quat_rotate(q, x) + p``.
Every function has one overload per float dtype (see ``float_overloads.py``) and
follows Warp 1.19. ``t1 * t2`` is ``transform_multiply``; ``t.p``/``t.q`` read and
assign the two parts (``kdsl/frontend/geometry.py``). ``transform_set_translation``
and ``transform_set_rotation`` write their first argument back when it is a local
variable (an ``inout`` parameter); passed an array element, they change a copy.
"""

import kdsl as wp
from kdsl.frontend.inout import inout
from kdsl.frontend.kernel import func
from kdsl.stdlib.float_overloads import define_float_overloads, functions_in
from kdsl.stdlib.quat import quat_from_matrix, quat_inverse, quat_multiply, quat_rotate
from kdsl.stdlib.quat import quat_to_matrix as _quat_to_matrix
from kdsl.types import matrix, quaternion, transformation, vector

__kdsl_group__ = "transform"


def _transform_functions(S: type) -> dict:
    Q = quaternion(S)
    V3 = vector(3, S)
    V4 = vector(4, S)
    M33 = matrix((3, 3), S)
    M44 = matrix((4, 4), S)
    T = transformation(S)

    @func
    def transform_get_translation(xform: T) -> V3:
        """The translation ``p`` of ``xform`` (components 0 to 2)."""
        return V3(xform[0], xform[1], xform[2])

    @func
    def transform_get_rotation(xform: T) -> Q:
        """The rotation ``q`` of ``xform`` (components 3 to 6), as stored (not normalized)."""
        return Q(xform[3], xform[4], xform[5], xform[6])

    @func
    def transform_set_translation_copy(xform: T, p: V3) -> T:
        """A copy of ``xform`` with its translation replaced by ``p``."""
        return T(p, transform_get_rotation(xform))

    @func
    def transform_set_rotation_copy(xform: T, q: Q) -> T:
        """A copy of ``xform`` with its rotation replaced by ``q`` (not normalized)."""
        return T(transform_get_translation(xform), q)

    @func
    def transform_set_translation(xform: inout(T), p: V3):
        """Replace the translation of the variable ``xform`` by ``p`` (in place, as ``xform.p = p``)."""
        xform = transform_set_translation_copy(xform, p)

    @func
    def transform_set_rotation(xform: inout(T), q: Q):
        """Replace the rotation of the variable ``xform`` by ``q`` (in place, as ``xform.q = q``)."""
        xform = transform_set_rotation_copy(xform, q)

    @func
    def transform_multiply(a: T, b: T) -> T:
        """The composition ``a * b``: applies ``b``, then ``a``."""
        qa = transform_get_rotation(a)
        p = quat_rotate(qa, transform_get_translation(b)) + transform_get_translation(a)
        return T(p, quat_multiply(qa, transform_get_rotation(b)))

    @func
    def transform_inverse(xform: T) -> T:
        """The inverse of ``xform`` (its rotation must have unit length)."""
        q_inv = quat_inverse(transform_get_rotation(xform))
        return T(-quat_rotate(q_inv, transform_get_translation(xform)), q_inv)

    @func
    def transform_point(xform: T, point: V3) -> V3:
        """``point`` mapped by ``xform``: rotated, then translated."""
        return transform_get_translation(xform) + quat_rotate(transform_get_rotation(xform), point)

    @func
    def transform_point(mat: M44, point: V3) -> V3:  # noqa: F811 - the 4x4 matrix overload
        """``point`` mapped by the 4x4 matrix ``mat`` (homogeneous w = 1)."""
        out = mat @ V4(point[0], point[1], point[2], S(1.0))
        return V3(out[0], out[1], out[2])

    @func
    def transform_vector(xform: T, vec: V3) -> V3:
        """``vec`` rotated by ``xform``'s rotation; the translation is ignored."""
        return quat_rotate(transform_get_rotation(xform), vec)

    @func
    def transform_vector(mat: M44, vec: V3) -> V3:  # noqa: F811 - the 4x4 matrix overload
        """``vec`` mapped by the 4x4 matrix ``mat`` (homogeneous w = 0)."""
        out = mat @ V4(vec[0], vec[1], vec[2], S(0.0))
        return V3(out[0], out[1], out[2])

    @func
    def transform_from_matrix(mat: M44) -> T:
        """The transform of a 4x4 rigid matrix: translation from column 3, rotation from 3x3."""
        return T(V3(mat[0, 3], mat[1, 3], mat[2, 3]), quat_from_matrix(mat))

    @func
    def transform_to_matrix(xform: T) -> M44:
        """The 4x4 matrix of ``xform``: ``[[R, p], [0, 1]]``."""
        p = transform_get_translation(xform)
        r = _quat_to_matrix(transform_get_rotation(xform))
        return M44(
            r[0, 0], r[0, 1], r[0, 2], p[0],
            r[1, 0], r[1, 1], r[1, 2], p[1],
            r[2, 0], r[2, 1], r[2, 2], p[2],
            S(0.0), S(0.0), S(0.0), S(1.0),
        )  # fmt: skip

    @func
    def transform_compose(position: V3, rotation: Q, scale: V3) -> M44:
        """The 4x4 matrix ``[[R diag(scale), position], [0, 1]]`` of a scaled rigid transform."""
        r = _quat_to_matrix(rotation)
        return M44(
            scale[0] * r[0, 0], scale[1] * r[0, 1], scale[2] * r[0, 2], position[0],
            scale[0] * r[1, 0], scale[1] * r[1, 1], scale[2] * r[1, 2], position[1],
            scale[0] * r[2, 0], scale[1] * r[2, 1], scale[2] * r[2, 2], position[2],
            S(0.0), S(0.0), S(0.0), S(1.0),
        )  # fmt: skip

    @func
    def transform_decompose(m: M44) -> tuple:
        """``(position, rotation, scale)`` of a 4x4 matrix made by ``transform_compose``."""
        r = M33(m[0, 0], m[0, 1], m[0, 2], m[1, 0], m[1, 1], m[1, 2], m[2, 0], m[2, 1], m[2, 2])
        scale = V3(S(0.0), S(0.0), S(0.0))
        for c in range(3):
            col = V3(r[0, c], r[1, c], r[2, c])
            s = wp.length(col)
            scale[c] = s
            if s != S(0.0):  # a zero column stays zero (Warp's rule)
                col = col / s
                r[0, c] = col[0]
                r[1, c] = col[1]
                r[2, c] = col[2]
        return V3(m[0, 3], m[1, 3], m[2, 3]), quat_from_matrix(r), scale

    return functions_in(locals())


_FUNCTIONS = define_float_overloads(_transform_functions)
globals().update(_FUNCTIONS)

__all__ = sorted(_FUNCTIONS)
