"""Quaternions, transforms and spatial algebra on f32 and f64, with their edge cases.

References are NumPy float64 and written from the mathematics (rotation matrices,
the Hamilton product), not from kdsl's code. Where a result's sign is not
defined (``quat_from_matrix``), kernels output sign-free quantities. Edge rows:
identity and its antipode, 180-degree turns about each axis, zero axes and
angles, ``t`` = 0 and 1, zero and NaN quaternions, and, for ``normalize``,
components whose squares underflow or overflow in the kernel's precision (Warp's
rule: a length of zero gives the identity).
"""

import numpy as np

import kdsl as wp
from kdsl.testing.case import Case, f64

N = 24
_TYPES = (("f32", wp.float32, np.float32, ()), ("f64", wp.float64, np.float64, ("fp64",)))

# --- NumPy references (float64, quaternions as (x, y, z, w)) ----------------------


def qmul(a, b):
    """Hamilton product of quaternion arrays ``a * b``."""
    av, aw = a[..., :3], a[..., 3:]
    bv, bw = b[..., :3], b[..., 3:]
    v = aw * bv + bw * av + np.cross(av, bv)
    w = aw * bw - np.sum(av * bv, -1, keepdims=True)
    return np.concatenate([v, w], -1)


def qconj(q):
    return q * np.array([-1.0, -1.0, -1.0, 1.0])


def qmat(q):
    """Rotation matrices of unit quaternions."""
    x, y, z, w = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], -2)  # fmt: skip


def qrot(q, v):
    return np.einsum("...ij,...j->...i", qmat(q), v)


def qaxis(axis, angle):
    half = 0.5 * np.asarray(angle)[..., None]
    return np.concatenate([axis * np.sin(half), np.cos(half)], -1)


def _unit(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _quats(rng, n=N):
    """Unit quaternions; the first rows are the edge rotations."""
    q = _unit(rng, n)
    s = np.sqrt(0.5)
    q[:8] = [
        (0, 0, 0, 1),
        (0, 0, 0, -1),
        (1, 0, 0, 0),
        (0, 1, 0, 0),
        (0, 0, 1, 0),
        (s, s, 0, 0),
        (0, 0, np.sin(1e-4), np.cos(1e-4)),
        (-0.5, 0.5, -0.5, -0.5),
    ]
    return q  # fmt: skip


def _vecs(rng, n=N, lo=-3.0, hi=3.0):
    v = rng.uniform(lo, hi, (n, 3))
    v[0] = 0.0
    return v


def _rpy(q):
    x, y, z, w = np.moveaxis(q, -1, 0)
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1, 1))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.stack([roll, pitch, yaw], -1)


def _axis_quat(axis, angle):
    e = np.zeros(angle.shape + (3,))
    e[..., axis] = 1.0
    return qaxis(e, angle)


def _from_euler(e, i, j, k):
    return qmul(_axis_quat(k, e[:, k]), qmul(_axis_quat(j, e[:, j]), _axis_quat(i, e[:, i])))


def _slerp(a, b, t):
    d = np.sum(a * b, -1, keepdims=True)
    b = np.where(d < 0, -b, b)  # the shortest arc
    rel = qmul(qconj(a), b)
    v = rel[:, :3]
    n = np.linalg.norm(v, axis=1, keepdims=True)
    axis = np.divide(v, n, out=np.zeros_like(v), where=n > 0)
    angle = 2 * np.arctan2(n[:, 0], np.abs(rel[:, 3]))
    return qmul(a, qaxis(axis, t * angle))


def _tmat(p, q):
    m = np.zeros(p.shape[:-1] + (4, 4))
    m[..., :3, :3] = qmat(q)
    m[..., :3, 3] = p
    m[..., 3, 3] = 1.0
    return m


def _skew_free_adjoint(r, s):
    out = np.zeros(r.shape[:-2] + (6, 6))
    out[..., :3, :3] = r
    out[..., 3:, 3:] = r
    out[..., 3:, :3] = s
    return out


# --- kernels: one family per float type ----------------------------------------------


def _kernels(S):
    Q = wp.quaternion(S)
    V3 = wp.vector(3, S)
    M33 = wp.matrix((3, 3), S)
    M44 = wp.matrix((4, 4), S)
    T = wp.transformation(S)
    SV = wp.vector(6, S)
    SM = wp.matrix((6, 6), S)
    k = {}

    def kernel(fn):
        k[fn.__name__] = wp.kernel(fn)
        return fn

    @kernel
    def quat_mul(a: wp.array(dtype=Q), b: wp.array(dtype=Q), ab: wp.array(dtype=Q),
                 ba: wp.array(dtype=Q)):  # fmt: skip
        i = wp.tid()
        ab[i] = a[i] * b[i]
        ba[i] = wp.mul(b[i], a[i])

    @kernel
    def quat_componentwise(a: wp.array(dtype=Q), b: wp.array(dtype=Q), s: wp.array(dtype=S),
                           out: wp.array(dtype=Q)):  # fmt: skip
        i = wp.tid()
        out[i] = a[i] * s[i] + s[i] * b[i] - a[i] / S(4.0) + (-b[i]) - (a[i] - b[i])

    @kernel
    def quat_inverse(a: wp.array(dtype=Q), out: wp.array(dtype=Q), prod: wp.array(dtype=Q)):
        i = wp.tid()
        out[i] = wp.quat_inverse(a[i])
        prod[i] = a[i] * wp.quat_inverse(a[i])

    @kernel
    def quat_rotate(q: wp.array(dtype=Q), v: wp.array(dtype=V3), out: wp.array(dtype=V3),
                    inv: wp.array(dtype=V3)):  # fmt: skip
        i = wp.tid()
        out[i] = wp.quat_rotate(q[i], v[i])
        inv[i] = wp.quat_rotate_inv(q[i], v[i])

    @kernel
    def quat_rotate_compose(a: wp.array(dtype=Q), b: wp.array(dtype=Q), v: wp.array(dtype=V3),
                            out: wp.array(dtype=V3)):  # fmt: skip
        i = wp.tid()
        out[i] = wp.quat_rotate(a[i] * b[i], v[i]) - wp.quat_rotate(
            a[i], wp.quat_rotate(b[i], v[i])
        )

    @kernel
    def quat_to_matrix(q: wp.array(dtype=Q), out: wp.array(dtype=M33)):
        i = wp.tid()
        out[i] = wp.quat_to_matrix(q[i])

    @kernel
    def quat_from_matrix(m: wp.array(dtype=M33), q: wp.array(dtype=Q), back: wp.array(dtype=M33),
                         align: wp.array(dtype=S), norm: wp.array(dtype=S)):  # fmt: skip
        i = wp.tid()
        r = wp.quat_from_matrix(m[i])
        back[i] = wp.quat_to_matrix(r)
        align[i] = wp.abs(wp.dot(r, q[i]))
        norm[i] = wp.length(r)

    @kernel
    def quat_from_matrix44(m: wp.array(dtype=M44), q: wp.array(dtype=Q), align: wp.array(dtype=S)):
        i = wp.tid()
        align[i] = wp.abs(wp.dot(wp.quat_from_matrix(m[i]), q[i]))

    @kernel
    def quat_from_axis_angle(axis: wp.array(dtype=V3), angle: wp.array(dtype=S),
                             out: wp.array(dtype=Q)):  # fmt: skip
        i = wp.tid()
        out[i] = wp.quat_from_axis_angle(axis[i], angle[i])

    @kernel
    def quat_to_axis_angle(
        q: wp.array(dtype=Q), axis: wp.array(dtype=V3), angle: wp.array(dtype=S)
    ):
        i = wp.tid()
        a, t = wp.quat_to_axis_angle(q[i])
        axis[i] = a
        angle[i] = t

    @kernel
    def quat_rpy(e: wp.array(dtype=V3), out: wp.array(dtype=Q), back: wp.array(dtype=V3)):
        i = wp.tid()
        q = wp.quat_rpy(e[i][0], e[i][1], e[i][2])
        out[i] = q
        back[i] = wp.quat_to_rpy(q)

    @kernel
    def quat_to_rpy(q: wp.array(dtype=Q), out: wp.array(dtype=V3)):
        i = wp.tid()
        out[i] = wp.quat_to_rpy(q[i])

    @kernel
    def quat_from_euler(e: wp.array(dtype=V3), xyz: wp.array(dtype=Q), zyx: wp.array(dtype=Q),
                        yxz: wp.array(dtype=Q), xyx: wp.array(dtype=Q)):  # fmt: skip
        i = wp.tid()
        xyz[i] = wp.quat_from_euler(e[i], 0, 1, 2)
        zyx[i] = wp.quat_from_euler(e[i], 2, 1, 0)
        yxz[i] = wp.quat_from_euler(e[i], 1, 0, 2)
        xyx[i] = wp.quat_from_euler(e[i], 0, 1, 0)

    @kernel
    def quat_to_euler(q: wp.array(dtype=Q), xyz: wp.array(dtype=V3), align: wp.array(dtype=S)):
        i = wp.tid()
        e = wp.quat_to_euler(q[i], 0, 1, 2)  # angles may come 2 pi apart from the rpy ones
        xyz[i] = V3(wp.atan2(wp.sin(e[0]), wp.cos(e[0])), wp.atan2(wp.sin(e[1]), wp.cos(e[1])),
                    wp.atan2(wp.sin(e[2]), wp.cos(e[2])))  # fmt: skip
        # Tait-Bryan orders round-trip to the same rotation (up to sign).
        s = S(0.0)
        for o in range(6):
            a = o % 3
            b = (a + 1 + o // 3) % 3
            c = 3 - a - b
            s += wp.abs(wp.dot(wp.quat_from_euler(wp.quat_to_euler(q[i], a, b, c), a, b, c), q[i]))
        align[i] = s

    @kernel
    def quat_slerp(a: wp.array(dtype=Q), b: wp.array(dtype=Q), t: wp.array(dtype=S),
                   out: wp.array(dtype=Q)):  # fmt: skip
        i = wp.tid()
        out[i] = wp.quat_slerp(a[i], b[i], t[i])

    @kernel
    def quat_slerp_geodesic(a: wp.array(dtype=Q), b: wp.array(dtype=Q), t: wp.array(dtype=S),
                            angle: wp.array(dtype=S), unit: wp.array(dtype=S)):  # fmt: skip
        # Slerp moves along the great arc at a constant rate: angle(a, slerp) = t angle(a, b).
        i = wp.tid()
        r = wp.quat_slerp(a[i], b[i], t[i])
        d = wp.min(wp.abs(wp.dot(r, a[i])), S(1.0))
        angle[i] = S(2.0) * wp.atan2(wp.sqrt(S(1.0) - d * d), d)
        unit[i] = wp.length(r)

    @kernel
    def quat_normalize(q: wp.array(dtype=Q), out: wp.array(dtype=Q), n: wp.array(dtype=S)):
        i = wp.tid()
        out[i] = wp.normalize(q[i])
        n[i] = wp.length(q[i])

    @kernel
    def quat_twist(axis: wp.array(dtype=V3), q: wp.array(dtype=Q), out: wp.array(dtype=Q),
                   ang: wp.array(dtype=S), signed: wp.array(dtype=S)):  # fmt: skip
        i = wp.tid()
        out[i] = wp.quat_twist(axis[i], q[i])
        ang[i] = wp.quat_twist_angle(axis[i], q[i])
        signed[i] = wp.quat_twist_angle_signed(axis[i], q[i])

    @kernel
    def quat_identity(out: wp.array(dtype=Q), comp: wp.array(dtype=S)):
        i = wp.tid()
        q = wp.quat_identity(dtype=S)
        out[i] = q
        comp[i] = q.x + S(2.0) * q.y + S(3.0) * q.z + S(4.0) * q.w + wp.length(Q())

    @kernel
    def transform_point(p: wp.array(dtype=V3), q: wp.array(dtype=Q), v: wp.array(dtype=V3),
                        point: wp.array(dtype=V3), vec: wp.array(dtype=V3)):  # fmt: skip
        i = wp.tid()
        t = T(p[i], q[i])
        point[i] = wp.transform_point(t, v[i])
        vec[i] = wp.transform_vector(t, v[i])

    @kernel
    def transform_point_matrix(m: wp.array(dtype=M44), v: wp.array(dtype=V3),
                               point: wp.array(dtype=V3), vec: wp.array(dtype=V3)):  # fmt: skip
        i = wp.tid()
        point[i] = wp.transform_point(m[i], v[i])
        vec[i] = wp.transform_vector(m[i], v[i])

    @kernel
    def transform_multiply(p: wp.array(dtype=V3), q: wp.array(dtype=Q), p2: wp.array(dtype=V3),
                           q2: wp.array(dtype=Q), op: wp.array(dtype=T),
                           fn: wp.array(dtype=T)):  # fmt: skip
        i = wp.tid()
        a = T(p[i], q[i])
        b = T(p2[i], q2[i])
        op[i] = a * b
        fn[i] = wp.transform_multiply(b, a)

    @kernel
    def transform_inverse(p: wp.array(dtype=V3), q: wp.array(dtype=Q), out: wp.array(dtype=T),
                          ident: wp.array(dtype=T)):  # fmt: skip
        i = wp.tid()
        t = T(p[i], q[i])
        out[i] = wp.transform_inverse(t)
        ident[i] = t * wp.transform_inverse(t)

    @kernel
    def transform_matrix(p: wp.array(dtype=V3), q: wp.array(dtype=Q), m: wp.array(dtype=M44),
                         back: wp.array(dtype=V3), align: wp.array(dtype=S)):  # fmt: skip
        i = wp.tid()
        mat = wp.transform_to_matrix(T(p[i], q[i]))
        m[i] = mat
        t = wp.transform_from_matrix(mat)
        back[i] = t.p
        align[i] = wp.abs(wp.dot(t.q, q[i]))

    @kernel
    def transform_compose(p: wp.array(dtype=V3), q: wp.array(dtype=Q), s: wp.array(dtype=V3),
                          m: wp.array(dtype=M44), pos: wp.array(dtype=V3),
                          scale: wp.array(dtype=V3), align: wp.array(dtype=S)):  # fmt: skip
        i = wp.tid()
        mat = wp.transform_compose(p[i], q[i], s[i])
        m[i] = mat
        a, r, c = wp.transform_decompose(mat)
        pos[i] = a
        scale[i] = c
        align[i] = wp.abs(wp.dot(r, q[i]))

    @kernel
    def transform_parts(p: wp.array(dtype=V3), q: wp.array(dtype=Q), p2: wp.array(dtype=V3),
                        q2: wp.array(dtype=Q), a: wp.array(dtype=T), b: wp.array(dtype=T),
                        c: wp.array(dtype=T), d: wp.array(dtype=V3)):  # fmt: skip
        i = wp.tid()
        t = T(p[i], q[i])
        x = t
        wp.transform_set_translation(x, p2[i])
        a[i] = x
        y = wp.transform_identity(dtype=S)
        y.q = q2[i]
        y.p += p2[i]
        y.p *= S(2.0)
        b[i] = y
        c[i] = wp.transform_set_rotation_copy(t, q2[i])
        d[i] = wp.transform_get_translation(t) + wp.quat_rotate(
            t.q, wp.transform_get_translation(y)
        )

    @kernel
    def transform_componentwise(p: wp.array(dtype=V3), q: wp.array(dtype=Q), s: wp.array(dtype=S),
                                out: wp.array(dtype=T)):  # fmt: skip
        i = wp.tid()
        t = T(p[i], q[i])
        out[i] = t * s[i] + (-t) - s[i] * t + t + t

    @kernel
    def spatial_parts(a: wp.array(dtype=V3), b: wp.array(dtype=V3), top: wp.array(dtype=V3),
                      bottom: wp.array(dtype=V3), dot: wp.array(dtype=S),
                      zero: wp.array(dtype=SV)):  # fmt: skip
        i = wp.tid()
        x = SV(a[i], b[i])
        y = SV(b[i][0], b[i][1], b[i][2], a[i][0], a[i][1], a[i][2])
        top[i] = wp.spatial_top(x)
        bottom[i] = wp.spatial_bottom(y)
        dot[i] = wp.spatial_dot(x, y)
        zero[i] = SV() + x - x

    @kernel
    def spatial_cross(a: wp.array(dtype=V3), b: wp.array(dtype=V3), c: wp.array(dtype=V3),
                      motion: wp.array(dtype=SV), force: wp.array(dtype=SV)):  # fmt: skip
        i = wp.tid()
        x = SV(a[i], b[i])
        y = SV(c[i], a[i] - b[i])
        motion[i] = wp.spatial_cross(x, y)
        force[i] = wp.spatial_cross_dual(x, y)

    @kernel
    def spatial_adjoint(q: wp.array(dtype=Q), p: wp.array(dtype=V3), v: wp.array(dtype=V3),
                        m: wp.array(dtype=SM), moved: wp.array(dtype=SV),
                        twist: wp.array(dtype=SV)):  # fmt: skip
        i = wp.tid()
        r = wp.quat_to_matrix(q[i])
        px = M33(S(0.0), -p[i][2], p[i][1], p[i][2], S(0.0), -p[i][0], -p[i][1], p[i][0], S(0.0))
        adj = wp.spatial_adjoint(r, px @ r)
        m[i] = adj
        x = SV(v[i], p[i] - v[i])
        moved[i] = adj @ x
        twist[i] = wp.transform_twist(T(p[i], q[i]), x)

    @kernel
    def transform_wrench(q: wp.array(dtype=Q), p: wp.array(dtype=V3), v: wp.array(dtype=V3),
                         out: wp.array(dtype=SV), vel: wp.array(dtype=V3)):  # fmt: skip
        i = wp.tid()
        x = SV(v[i], p[i] - v[i])
        out[i] = wp.transform_wrench(T(p[i], q[i]), x)
        vel[i] = wp.velocity_at_point(x, p[i])

    @kernel
    def quat_components(q: wp.array(dtype=Q), out: wp.array(dtype=Q), comp: wp.array(dtype=S)):
        i = wp.tid()
        x = q[i]
        x.w = x.x + x[3]
        x[0] += S(1.0)
        x.y *= S(2.0)
        out[i] = x
        s = S(0.0)
        for k in range(4):
            s += S(k + 1) * q[i][k]
        comp[i] = s + q[i][-1] + wp.dot(q[i], x) + wp.length(q[i]) + wp.length_sq(x)

    @kernel
    def quat_axis_angle_roundtrip(q: wp.array(dtype=Q), align: wp.array(dtype=S),
                                  rot: wp.array(dtype=V3), v: wp.array(dtype=V3)):  # fmt: skip
        i = wp.tid()
        axis, angle = wp.quat_to_axis_angle(q[i])
        r = wp.quat_from_axis_angle(axis, angle)
        align[i] = wp.abs(wp.dot(r, wp.normalize(q[i])))
        rot[i] = wp.quat_rotate(r, v[i])

    @kernel
    def quat_identity_laws(q: wp.array(dtype=Q), v: wp.array(dtype=V3), left: wp.array(dtype=Q),
                           right: wp.array(dtype=Q), rot: wp.array(dtype=V3)):  # fmt: skip
        i = wp.tid()
        e = wp.quat_identity(S)
        left[i] = e * q[i]
        right[i] = q[i] * e
        rot[i] = wp.quat_rotate(e, v[i]) + wp.quat_rotate_inv(e, v[i])

    @kernel
    def quat_rotate_extremes(q: wp.array(dtype=Q), v: wp.array(dtype=V3), out: wp.array(dtype=V3)):
        # Huge and tiny vectors: no overflow or flush on the way; compared at |v|'s scale.
        i = wp.tid()
        x = v[i]
        out[i] = wp.quat_rotate(q[i], x) / wp.max(wp.abs(x[0]), wp.abs(x[1]), wp.abs(x[2]))

    @kernel
    def geometry_nonfinite(q: wp.array(dtype=Q), p: wp.array(dtype=V3), v: wp.array(dtype=V3),
                           rot: wp.array(dtype=V3), point: wp.array(dtype=V3),
                           prod: wp.array(dtype=Q)):  # fmt: skip
        i = wp.tid()
        rot[i] = wp.quat_rotate(q[i], v[i])
        point[i] = wp.transform_point(T(p[i], q[i]), v[i])
        prod[i] = q[i] * q[i]

    @kernel
    def quat_swing_twist(axis: wp.array(dtype=V3), q: wp.array(dtype=Q), along: wp.array(dtype=S),
                         back: wp.array(dtype=S)):  # fmt: skip
        i = wp.tid()
        tw = wp.quat_twist(axis[i], q[i])
        swing = q[i] * wp.quat_inverse(tw)
        along[i] = wp.dot(V3(swing[0], swing[1], swing[2]), axis[i])
        back[i] = wp.abs(wp.dot(swing * tw, q[i]))

    @kernel
    def transform_chain(p: wp.array(dtype=V3), q: wp.array(dtype=Q), n: int,
                        out: wp.array(dtype=V3), total: wp.array(dtype=T)):  # fmt: skip
        i = wp.tid()
        acc = wp.transform_identity(S)
        x = p[i]
        for k in range(n):
            t = T(p[(i + k) % len(p)], q[(i + k) % len(q)])
            acc = acc * t
            x = wp.transform_point(t, x)
        # acc = t0 * t1 * ... ; x = t_{n-1}(...t0(p))
        out[i] = x - wp.transform_point(wp.transform_inverse(acc), wp.transform_point(acc, x))
        total[i] = acc * wp.transform_inverse(acc)

    @kernel
    def transform_components(p: wp.array(dtype=V3), q: wp.array(dtype=Q), out: wp.array(dtype=T),
                             comp: wp.array(dtype=S)):  # fmt: skip
        i = wp.tid()
        t = T(p[i], q[i])
        t.p.x = t[6]
        t[3] = t.q.w + S(1.0)
        t.q.z -= S(2.0)
        out[i] = t
        comp[i] = t.p.y + S(2.0) * t.q[1] + t[-1]

    @kernel
    def spatial_matrix_ops(a: wp.array(dtype=V3), b: wp.array(dtype=V3), mv: wp.array(dtype=SV),
                           mt: wp.array(dtype=SM), row: wp.array(dtype=SV)):  # fmt: skip
        i = wp.tid()
        x = SV(a[i], b[i])
        y = SV(b[i], a[i])
        m = wp.outer(x, y) + SM(S(1.0))
        mv[i] = m @ x
        mt[i] = wp.transpose(m) * S(2.0)
        row[i] = m[2]

    return k


# --- input generators and references, by kernel name -------------------------------------


def _in_mul(rng):
    a, b = _quats(rng), _quats(rng)[::-1].copy()
    return {"a": a, "b": b}


def _in_rot(rng):
    return {"q": _quats(rng), "v": _vecs(rng)}


def _in_axis_angle(rng):
    axis = _vecs(rng)
    axis[1:] /= np.linalg.norm(axis[1:], axis=1, keepdims=True)
    angle = rng.uniform(-7.0, 7.0, N)
    angle[:6] = [1.0, 0.0, np.pi, -np.pi, 2 * np.pi, 100.0]
    return {"axis": axis, "angle": angle}


def _in_matrix(rng):
    q = _quats(rng)
    # Near-degenerate: turns of pi - 1e-3 (trace near -1, where the w path is unstable).
    for r, ax in zip(range(8, 11), np.eye(3)):
        q[r] = qaxis(ax, np.pi - 1e-3)
    q = q * np.where(q[:, 3:] < 0, -1.0, 1.0)
    return {"q": q, "m": qmat(q)}


def _in_euler(rng):
    e = rng.uniform(-np.pi, np.pi, (N, 3))
    e[:, 1] = rng.uniform(-1.4, 1.4, N)  # pitch away from gimbal lock
    e[:4] = [(0, 0, 0), (3.1, 0, 0), (0, 0, -3.1), (0.3, -0.2, 0.1)]
    return {"e": e}


def _in_slerp(rng):
    a, b = _quats(rng), _unit(rng, N)
    t = rng.uniform(0, 1, N)
    t[:4] = [0.0, 1.0, 0.0, 1.0]
    b[4], b[5] = -a[4], a[5]  # antipodal and equal
    b[6] = -qmul(a[6], qaxis(np.array([0, 0, 1.0]), 0.5))  # b on the far hemisphere
    return {"a": a, "b": b, "t": t}


def _in_normalize(rng, np_dtype):
    q = rng.normal(size=(N, 4)) * 3
    tiny = 1e-30 if np_dtype == np.float32 else 1e-200
    huge = 1e30 if np_dtype == np.float32 else 1e200
    q[:6] = [(0, 0, 0, 0), (-0.0, 0, 0, 0), (tiny, 0, 0, 0), (tiny, tiny, -tiny, tiny),
             (huge, 0, 0, 0), (np.nan, 1, 0, 0)]  # fmt: skip
    q[6] = (0, 0, 0, -2.5)
    return {"q": q}


def _normalize_ref(ins):
    q = ins["q"]
    dt = q.dtype.type
    with np.errstate(all="ignore"):
        n = np.sqrt(np.sum(q * q, axis=1, dtype=q.dtype))  # in the kernel's precision
        out = f64(q) * f64(dt(1) / n)[:, None]
    out[n == 0] = (0, 0, 0, 1)  # Warp: a zero length gives the identity
    return {"out": out, "n": f64(n)}


def _to_axis_angle_ref(ins):
    q = f64(ins["q"])
    v = q[:, :3]
    n = np.linalg.norm(v, axis=1, keepdims=True)
    axis = np.divide(v, n, out=np.zeros_like(v), where=n > 0) * np.where(q[:, 3:] < 0, -1, 1)
    return {"axis": axis, "angle": 2 * np.arctan2(n[:, 0], np.abs(q[:, 3]))}


def _twist_ref(ins):
    axis, q = f64(ins["axis"]), f64(ins["q"])
    proj = np.sum(q[:, :3] * axis, 1)
    tw = np.concatenate([axis * proj[:, None], q[:, 3:]], 1)
    return {
        "out": tw / np.linalg.norm(tw, axis=1, keepdims=True),
        "ang": 2 * np.arctan2(np.abs(proj), q[:, 3]),
        "signed": 2 * np.arctan2(proj, q[:, 3]),
    }


def _in_twist(rng):
    axis = _vecs(rng)
    axis[0] = (0, 0, 1)
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    q = _quats(rng)
    q[1] = (0, 0, 0.6, -0.8)  # w < 0: the unsigned angle is past pi
    return {"axis": axis, "q": q}


def _in_transform(rng):
    return {"p": _vecs(rng), "q": _quats(rng), "v": _vecs(rng)[::-1].copy()}


def _in_transform2(rng):
    return {"p": _vecs(rng), "q": _quats(rng), "p2": _vecs(rng)[::-1].copy(),
            "q2": _quats(rng)[::-1].copy()}  # fmt: skip


def _tcat(p, q):
    return np.concatenate([p, q], 1)


def _tmul(p, q, p2, q2):
    return _tcat(qrot(q, p2) + p, qmul(q, q2))


def _in_compose(rng):
    d = _in_transform(rng)
    s = rng.uniform(0.2, 3.0, (N, 3))
    s[0] = (1, 1, 1)
    return {"p": d["p"], "q": d["q"], "s": s}


def _compose_ref(ins):
    p, q, s = f64(ins["p"]), f64(ins["q"]), f64(ins["s"])
    m = _tmat(p, q)
    m[:, :3, :3] *= s[:, None, :]
    return {"m": m, "pos": p, "scale": s, "align": np.ones(len(p))}


def _in_matrix44(rng):
    d = _in_matrix(rng)
    m = _tmat(_vecs(rng), d["q"])
    return {"m": m, "q": d["q"]}


def _in_point_matrix(rng):
    m = rng.uniform(-2, 2, (N, 4, 4))
    return {"m": m, "v": _vecs(rng)}


def _point_matrix_ref(ins):
    m, v = f64(ins["m"]), f64(ins["v"])
    return {"point": np.einsum("nij,nj->ni", m[:, :3, :3], v) + m[:, :3, 3],
            "vec": np.einsum("nij,nj->ni", m[:, :3, :3], v)}  # fmt: skip


def _in_three(rng):
    return {"a": _vecs(rng), "b": _vecs(rng)[::-1].copy(), "c": rng.uniform(-1, 1, (N, 3))}


def _scross(x, y, dual):
    xw, xv, yw, yv = x[:, :3], x[:, 3:], y[:, :3], y[:, 3:]
    if dual:
        return np.concatenate([np.cross(xw, yw) + np.cross(xv, yv), np.cross(xw, yv)], 1)
    return np.concatenate([np.cross(xw, yw), np.cross(xv, yw) + np.cross(xw, yv)], 1)


def _spatial_cross_ref(ins):
    a, b, c = f64(ins["a"]), f64(ins["b"]), f64(ins["c"])
    x, y = np.concatenate([a, b], 1), np.concatenate([c, a - b], 1)
    return {"motion": _scross(x, y, False), "force": _scross(x, y, True)}


def _in_adjoint(rng):
    return {"q": _quats(rng), "p": _vecs(rng), "v": _vecs(rng)[::-1].copy()}


def _adjoint_ref(ins):
    q, p, v = f64(ins["q"]), f64(ins["p"]), f64(ins["v"])
    r = qmat(q)
    px = np.zeros((len(p), 3, 3))
    px[:, 0, 1], px[:, 0, 2], px[:, 1, 2] = -p[:, 2], p[:, 1], -p[:, 0]
    px -= np.transpose(px, (0, 2, 1))
    adj = _skew_free_adjoint(r, px @ r)
    x = np.concatenate([v, p - v], 1)
    w = qrot(q, v)
    twist = np.concatenate([w, qrot(q, p - v) + np.cross(p, w)], 1)
    return {"m": adj, "moved": np.einsum("nij,nj->ni", adj, x), "twist": twist}


def _wrench_ref(ins):
    q, p, v = f64(ins["q"]), f64(ins["p"]), f64(ins["v"])
    f = qrot(q, p - v)
    return {"out": np.concatenate([qrot(q, v) + np.cross(p, f), f], 1),
            "vel": (p - v) + np.cross(v, p)}  # fmt: skip


def _euler_ref(ins):
    e = f64(ins["e"])
    return {"xyz": _from_euler(e, 0, 1, 2), "zyx": _from_euler(e, 2, 1, 0),
            "yxz": _from_euler(e, 1, 0, 2), "xyx": _from_euler(e, 0, 1, 0)}  # fmt: skip


def _in_to_rpy(rng):
    q = _quats(rng)
    q[8] = (0, 1.2, 0, 1)  # not unit: the pitch term is 2.4, clamped to 1
    return {"q": q}


def _in_geodesic(rng):
    d = _in_slerp(rng)
    d["b"][5] = _unit(rng, 1)[0]  # no equal pair: the angle is ill-conditioned at zero
    return d


def _geodesic_ref(ins):
    a, b, t = f64(ins["a"]), f64(ins["b"]), f64(ins["t"])
    d = np.minimum(np.abs(np.sum(a * b, 1)), 1.0)
    return {"angle": t * 2 * np.arccos(d), "unit": np.ones(len(t))}


def _normalized(q):
    q = f64(q)
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _components_ref(ins):
    q = f64(ins["q"])
    x = q.copy()
    x[:, 3] = x[:, 0] + x[:, 3]
    x[:, 0] += 1
    x[:, 1] *= 2
    comp = q @ [1.0, 2, 3, 4] + q[:, 3] + np.sum(q * x, 1) + np.linalg.norm(q, axis=1)
    return {"out": x, "comp": comp + np.sum(x * x, 1)}


def _in_extremes(rng, np_dtype):
    big = 1e30 if np_dtype == np.float32 else 1e300
    tiny = 1e-30 if np_dtype == np.float32 else 1e-300
    v = rng.uniform(-1, 1, (N, 3))
    v[: N // 2] *= big
    v[N // 2 :] *= tiny
    return {"q": _quats(rng), "v": v}


def _in_nonfinite(rng):
    q, p, v = _quats(rng), _vecs(rng), _vecs(rng)[::-1].copy()
    q[1, 0], p[2, 1], v[3, 2] = np.nan, np.inf, -np.inf
    return {"q": q, "p": p, "v": v}


def _nonfinite_ref(ins):
    q, p, v = f64(ins["q"]), f64(ins["p"]), f64(ins["v"])
    with np.errstate(all="ignore"):
        rot = qrot(q, v)
        prod = qmul(q, q)
    bad_q = ~np.all(np.isfinite(q), 1)
    rot[bad_q | ~np.all(np.isfinite(v), 1)] = np.nan  # every term of the rotation meets it
    prod[bad_q] = np.nan
    point = rot + p
    return {"rot": rot, "point": point, "prod": prod}


def _transform_components_ref(ins):
    t = _tcat(f64(ins["p"]), f64(ins["q"]))
    t[:, 0] = t[:, 6]
    t[:, 3] = t[:, 6] + 1
    t[:, 5] -= 2
    return {"out": t, "comp": t[:, 1] + 2 * t[:, 4] + t[:, 6]}


def _spatial_matrix_ref(ins):
    a, b = f64(ins["a"]), f64(ins["b"])
    x, y = np.concatenate([a, b], 1), np.concatenate([b, a], 1)
    m = x[:, :, None] * y[:, None, :] + 1
    return {"mv": np.einsum("nij,nj->ni", m, x), "mt": 2 * np.transpose(m, (0, 2, 1)),
            "row": m[:, 2]}  # fmt: skip


#: name -> (inputs(rng, np_dtype), reference(inputs), outputs, tolerance per (f32, f64))
_SPEC = {
    "quat_mul": (lambda rng, dt: _in_mul(rng),
                 lambda i: {"ab": qmul(f64(i["a"]), f64(i["b"])),
                            "ba": qmul(f64(i["b"]), f64(i["a"]))}, ("ab", "ba"), None),
    "quat_componentwise": (lambda rng, dt: {**_in_mul(rng), "s": rng.uniform(-2, 2, N)},
                           lambda i: {"out": f64(i["a"]) * f64(i["s"])[:, None]
                                      + f64(i["s"])[:, None] * f64(i["b"]) - f64(i["a"]) / 4
                                      - f64(i["b"]) - (f64(i["a"]) - f64(i["b"]))},
                           ("out",), None),
    "quat_inverse": (lambda rng, dt: {"a": _quats(rng) * rng.uniform(0.5, 2, (N, 1))},
                     lambda i: {"out": qconj(f64(i["a"])),
                                "prod": np.outer(np.sum(f64(i["a"]) ** 2, 1), [0, 0, 0, 1])},
                     ("out", "prod"), None),
    "quat_rotate": (lambda rng, dt: _in_rot(rng),
                    lambda i: {"out": qrot(f64(i["q"]), f64(i["v"])),
                               "inv": qrot(qconj(f64(i["q"])), f64(i["v"]))}, ("out", "inv"),
                    (2e-6, 2e-6)),
    "quat_rotate_compose": (lambda rng, dt: {**_in_mul(rng), "v": _vecs(rng)},
                            lambda i: {"out": np.zeros((N, 3))}, ("out",), (1e-5, 1e-5)),
    "quat_to_matrix": (lambda rng, dt: {"q": _quats(rng)}, lambda i: {"out": qmat(f64(i["q"]))},
                       ("out",), (2e-6, 2e-6)),
    "quat_from_matrix": (lambda rng, dt: _in_matrix(rng),
                         lambda i: {"back": f64(i["m"]), "align": np.ones(N), "norm": np.ones(N)},
                         ("back", "align", "norm"), (2e-5, 2e-5)),
    "quat_from_matrix44": (lambda rng, dt: _in_matrix44(rng), lambda i: {"align": np.ones(N)},
                           ("align",), (2e-5, 2e-5)),
    "quat_from_axis_angle": (lambda rng, dt: _in_axis_angle(rng),
                             lambda i: {"out": qaxis(f64(i["axis"]), f64(i["angle"]))},
                             ("out",), (1e-5, 5e-6)),
    "quat_to_axis_angle": (lambda rng, dt: {"q": _quats(rng)}, _to_axis_angle_ref,
                           ("axis", "angle"), (2e-5, 2e-5)),
    "quat_rpy": (lambda rng, dt: _in_euler(rng),
                 lambda i: {"out": _from_euler(f64(i["e"]), 0, 1, 2),
                            "back": _rpy(_from_euler(f64(i["e"]), 0, 1, 2))},
                 ("out", "back"), (2e-5, 2e-5)),
    "quat_to_rpy": (lambda rng, dt: _in_to_rpy(rng), lambda i: {"out": _rpy(f64(i["q"]))},
                    ("out",), (2e-5, 2e-5)),
    "quat_from_euler": (lambda rng, dt: _in_euler(rng), _euler_ref,
                        ("xyz", "zyx", "yxz", "xyx"), (2e-6, 2e-6)),
    "quat_to_euler": (lambda rng, dt: {"q": _quats(rng)[N - _ROWS["quat_to_euler"]:]},
                      lambda i: {"xyz": _rpy(f64(i["q"])), "align": np.full(len(i["q"]), 6.0)},
                      ("xyz", "align"), (5e-5, 5e-5)),
    "quat_slerp": (lambda rng, dt: _in_slerp(rng),
                   lambda i: {"out": _slerp(f64(i["a"]), f64(i["b"]), f64(i["t"]))},
                   ("out",), (2e-5, 2e-5)),
    "quat_slerp_geodesic": (lambda rng, dt: _in_geodesic(rng), _geodesic_ref, ("angle", "unit"),
                            (1e-4, 1e-4)),
    "quat_normalize": (_in_normalize, _normalize_ref, ("out", "n"), None),
    "quat_twist": (lambda rng, dt: _in_twist(rng), _twist_ref, ("out", "ang", "signed"),
                   (2e-5, 2e-5)),
    "quat_identity": (lambda rng, dt: {}, lambda i: {"out": np.tile([0, 0, 0, 1.0], (N, 1)),
                                                     "comp": np.full(N, 4.0)},
                      ("out", "comp"), None),
    "transform_point": (lambda rng, dt: _in_transform(rng),
                        lambda i: {"point": qrot(f64(i["q"]), f64(i["v"])) + f64(i["p"]),
                                   "vec": qrot(f64(i["q"]), f64(i["v"]))},
                        ("point", "vec"), (5e-6, 5e-6)),
    "transform_point_matrix": (lambda rng, dt: _in_point_matrix(rng), _point_matrix_ref,
                               ("point", "vec"), (5e-6, 5e-6)),
    "transform_multiply": (lambda rng, dt: _in_transform2(rng),
                           lambda i: {"op": _tmul(*map(f64, (i["p"], i["q"], i["p2"], i["q2"]))),
                                      "fn": _tmul(*map(f64, (i["p2"], i["q2"], i["p"], i["q"])))},
                           ("op", "fn"), (5e-6, 5e-6)),
    "transform_inverse": (lambda rng, dt: _in_transform(rng),
                          lambda i: {"out": _tcat(-qrot(qconj(f64(i["q"])), f64(i["p"])),
                                                  qconj(f64(i["q"]))),
                                     "ident": np.tile([0, 0, 0, 0, 0, 0, 1.0], (N, 1))},
                          ("out", "ident"), (5e-6, 5e-6)),
    "transform_matrix": (lambda rng, dt: _in_transform(rng),
                         lambda i: {"m": _tmat(f64(i["p"]), f64(i["q"])), "back": f64(i["p"]),
                                    "align": np.ones(N)}, ("m", "back", "align"), (2e-5, 2e-5)),
    "transform_compose": (lambda rng, dt: _in_compose(rng), _compose_ref,
                          ("m", "pos", "scale", "align"), (2e-5, 2e-5)),
    "transform_parts": (lambda rng, dt: _in_transform2(rng),
                        lambda i: {"a": _tcat(f64(i["p2"]), f64(i["q"])),
                                   "b": _tcat(2 * f64(i["p2"]), f64(i["q2"])),
                                   "c": _tcat(f64(i["p"]), f64(i["q2"])),
                                   "d": f64(i["p"]) + qrot(f64(i["q"]), 2 * f64(i["p2"]))},
                        ("a", "b", "c", "d"), (5e-6, 5e-6)),
    "transform_componentwise": (lambda rng, dt: {**_in_transform(rng), "s": rng.uniform(-2, 2, N)},
                                lambda i: {"out": _tcat(f64(i["p"]), f64(i["q"]))},
                                ("out",), (5e-6, 5e-6)),
    "spatial_parts": (lambda rng, dt: _in_three(rng),
                      lambda i: {"top": f64(i["a"]), "bottom": f64(i["a"]),
                                 "dot": 2 * np.sum(f64(i["a"]) * f64(i["b"]), 1),
                                 "zero": np.zeros((N, 6))},
                      ("top", "bottom", "dot", "zero"), None),
    "spatial_cross": (lambda rng, dt: _in_three(rng), _spatial_cross_ref, ("motion", "force"),
                      (5e-6, 5e-6)),
    "spatial_adjoint": (lambda rng, dt: _in_adjoint(rng), _adjoint_ref, ("m", "moved", "twist"),
                        (2e-5, 2e-5)),
    "transform_wrench": (lambda rng, dt: _in_adjoint(rng), _wrench_ref, ("out", "vel"),
                         (5e-6, 5e-6)),
    "quat_components": (lambda rng, dt: {"q": _quats(rng) * 2}, _components_ref,
                        ("out", "comp"), None),
    "quat_axis_angle_roundtrip": (lambda rng, dt: {"q": _quats(rng) * rng.uniform(0.5, 3, (N, 1)),
                                                   "v": _vecs(rng)},
                                  lambda i: {"align": np.ones(N),
                                             "rot": qrot(_normalized(i["q"]), f64(i["v"]))},
                                  ("align", "rot"), (2e-5, 2e-5)),
    "quat_identity_laws": (lambda rng, dt: _in_rot(rng),
                           lambda i: {"left": f64(i["q"]), "right": f64(i["q"]),
                                      "rot": 2 * f64(i["v"])}, ("left", "right", "rot"), None),
    "quat_rotate_extremes": (_in_extremes,
                             lambda i: {"out": qrot(f64(i["q"]), f64(i["v"]))
                                        / np.max(np.abs(f64(i["v"])), 1, keepdims=True)},
                             ("out",), (2e-6, 2e-6)),
    "geometry_nonfinite": (lambda rng, dt: _in_nonfinite(rng), _nonfinite_ref,
                           ("rot", "point", "prod"), None),
    "quat_swing_twist": (lambda rng, dt: _in_twist(rng),
                         lambda i: {"along": np.zeros(N), "back": np.ones(N)}, ("along", "back"),
                         (2e-5, 2e-5)),
    "transform_chain": (lambda rng, dt: {**_in_transform(rng), "n": 5},
                        lambda i: {"out": np.zeros((N, 3)),
                                   "total": np.tile([0, 0, 0, 0, 0, 0, 1.0], (N, 1))},
                        ("out", "total"), (5e-5, 5e-5)),
    "transform_components": (lambda rng, dt: _in_transform(rng), _transform_components_ref,
                             ("out", "comp"), None),
    "spatial_matrix_ops": (lambda rng, dt: _in_three(rng), _spatial_matrix_ref,
                           ("mv", "mt", "row"), (1e-5, 1e-5)),
}  # fmt: skip

#: Launch sizes that differ from N.
_ROWS = {"quat_to_euler": 16}


def _out_shape(kernel, name: str) -> tuple[int, ...]:
    from kdsl.ir import types as T

    idx = kernel.arg_names.index(name)
    t = kernel.arg_types[idx].dtype
    return T.value_shape(t)


def _cases() -> list[Case]:
    out = []
    for tname, dtype, np_dtype, req in _TYPES:
        kernels = _kernels(dtype)
        for name, (gen, ref, outputs, tol) in _SPEC.items():
            kernel = kernels[name]

            def make(rng, gen=gen, kernel=kernel, outputs=outputs, np_dtype=np_dtype,
                     kernel_name=name):  # fmt: skip
                ins = {k: np.asarray(v).astype(np_dtype) for k, v in gen(rng, np_dtype).items()}
                n = _ROWS.get(kernel_name, N)
                for o in outputs:
                    ins[o] = np.zeros((n, *_out_shape(kernel, o)), np_dtype)
                return ins

            case_tol = None if tol is None else (tol if tname == "f32" else (1e-11, 1e-11))
            rows = _ROWS.get(name, N)
            out.append(Case(f"geom_{name}_{tname}", kernel, rows, make, ref, outputs,
                            requires=req, tol=case_tol))  # fmt: skip
    return out


CASES: list[Case] = _cases()
