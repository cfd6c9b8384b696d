"""Matrix algorithms written in kdsl: determinant, inverse, QR, SVD and eigendecomposition.

Every function is defined once per float type (float16, float32, float64) by a
Python factory, so each is an ordinary ``@kdsl.func`` with one overload per type
and is compiled only when a kernel calls it.

Conventions (Warp's, see ``docs/semantics.md``):

- ``qr3(A) -> (Q, R)``: ``A = Q @ R``, ``Q`` orthogonal with determinant +1, ``R``
  upper triangular with ``R[0,0], R[1,1] >= 0`` (Givens rotations).
- ``svd3(A) -> (U, sigma, V)``: ``A = U @ diag(sigma) @ transpose(V)``, ``U`` and ``V``
  rotations (determinant +1), ``|sigma|`` decreasing, ``sigma[0], sigma[1] >= 0`` and
  ``sigma[2]`` carrying the sign of ``determinant(A)``.
- ``svd2(A) -> (U, sigma, V)``: ``sigma >= 0`` decreasing; ``U``, ``V`` orthogonal.
- ``eig3(A) -> (Q, d)`` for a symmetric ``A``: ``A = Q @ diag(d) @ transpose(Q)``, the
  columns of ``Q`` a right-handed orthonormal basis; no order is promised.

Warp also accepts output arguments (``svd3(A, U, sigma, V)``); kdsl functions
cannot assign to their arguments, so only the tuple-returning form exists.
The determinant and inverse are reached through the ``determinant``/``inverse``
builtins (``mat_determinant``/``mat_inverse`` here); an exactly singular matrix
(determinant 0) inverts to the zero matrix, as in Warp.
"""

import kdsl as wp
from kdsl import types as kt
from kdsl.frontend.kernel import func

__kdsl_group__ = "vector"
__all__ = ["eig3", "qr3", "svd2", "svd3"]

#: Jacobi sweeps (3 rotations each) per element type: convergence is quadratic, so a
#: few sweeps reach full precision.
_SWEEPS = {16: 4, 32: 6, 64: 10}


def _define_for(S, V2, V3, M22, M33, M44, sweeps):
    """Define every overload of this module for the scalar type ``S``."""
    global mat_determinant, mat_inverse, qr3, svd3, svd2, eig3
    V6 = kt.vector(6, S)

    @func
    def mat_determinant(m: M22) -> S:
        """Determinant of a 2x2 matrix."""
        return m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]

    @func
    def mat_determinant(m: M33) -> S:  # noqa: F811
        """Determinant of a 3x3 matrix (cofactors of the first row)."""
        return (m[0, 0] * (m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1])
                - m[0, 1] * (m[1, 0] * m[2, 2] - m[1, 2] * m[2, 0])
                + m[0, 2] * (m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0]))  # fmt: skip

    @func
    def _minors44(m: M44):
        # The 2x2 minors of rows 0-1 (s) and of rows 2-3 (c), shared by det and inverse.
        s = V6(m[0, 0] * m[1, 1] - m[1, 0] * m[0, 1], m[0, 0] * m[1, 2] - m[1, 0] * m[0, 2],
               m[0, 0] * m[1, 3] - m[1, 0] * m[0, 3], m[0, 1] * m[1, 2] - m[1, 1] * m[0, 2],
               m[0, 1] * m[1, 3] - m[1, 1] * m[0, 3], m[0, 2] * m[1, 3] - m[1, 2] * m[0, 3])
        c = V6(m[2, 0] * m[3, 1] - m[3, 0] * m[2, 1], m[2, 0] * m[3, 2] - m[3, 0] * m[2, 2],
               m[2, 0] * m[3, 3] - m[3, 0] * m[2, 3], m[2, 1] * m[3, 2] - m[3, 1] * m[2, 2],
               m[2, 1] * m[3, 3] - m[3, 1] * m[2, 3], m[2, 2] * m[3, 3] - m[3, 2] * m[2, 3])
        return s, c

    @func
    def _det44(s: V6, c: V6) -> S:
        return s[0] * c[5] - s[1] * c[4] + s[2] * c[3] + s[3] * c[2] - s[4] * c[1] + s[5] * c[0]

    @func
    def mat_determinant(m: M44) -> S:  # noqa: F811
        """Determinant of a 4x4 matrix (Laplace expansion by 2x2 minors of rows 0-1 and 2-3)."""
        s, c = _minors44(m)
        return _det44(s, c)

    @func
    def mat_inverse(m: M22) -> M22:
        """Inverse of a 2x2 matrix; the zero matrix when the determinant is 0."""
        det = mat_determinant(m)
        if det == S(0.0):
            return M22()
        inv = S(1.0) / det
        return M22(m[1, 1] * inv, -m[0, 1] * inv, -m[1, 0] * inv, m[0, 0] * inv)

    @func
    def mat_inverse(m: M33) -> M33:  # noqa: F811
        """Inverse of a 3x3 matrix (adjugate over determinant); zero when singular."""
        det = mat_determinant(m)
        if det == S(0.0):
            return M33()
        inv = S(1.0) / det
        return M33(
            (m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1]) * inv,
            (m[0, 2] * m[2, 1] - m[0, 1] * m[2, 2]) * inv,
            (m[0, 1] * m[1, 2] - m[0, 2] * m[1, 1]) * inv,
            (m[1, 2] * m[2, 0] - m[1, 0] * m[2, 2]) * inv,
            (m[0, 0] * m[2, 2] - m[0, 2] * m[2, 0]) * inv,
            (m[0, 2] * m[1, 0] - m[0, 0] * m[1, 2]) * inv,
            (m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0]) * inv,
            (m[0, 1] * m[2, 0] - m[0, 0] * m[2, 1]) * inv,
            (m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]) * inv,
        )

    @func
    def mat_inverse(m: M44) -> M44:  # noqa: F811
        """Inverse of a 4x4 matrix (adjugate by 2x2 minors); zero when singular."""
        s, c = _minors44(m)
        det = _det44(s, c)
        if det == S(0.0):
            return M44()
        inv = S(1.0) / det
        return M44(
            (m[1, 1] * c[5] - m[1, 2] * c[4] + m[1, 3] * c[3]) * inv,
            (-m[0, 1] * c[5] + m[0, 2] * c[4] - m[0, 3] * c[3]) * inv,
            (m[3, 1] * s[5] - m[3, 2] * s[4] + m[3, 3] * s[3]) * inv,
            (-m[2, 1] * s[5] + m[2, 2] * s[4] - m[2, 3] * s[3]) * inv,
            (-m[1, 0] * c[5] + m[1, 2] * c[2] - m[1, 3] * c[1]) * inv,
            (m[0, 0] * c[5] - m[0, 2] * c[2] + m[0, 3] * c[1]) * inv,
            (-m[3, 0] * s[5] + m[3, 2] * s[2] - m[3, 3] * s[1]) * inv,
            (m[2, 0] * s[5] - m[2, 2] * s[2] + m[2, 3] * s[1]) * inv,
            (m[1, 0] * c[4] - m[1, 1] * c[2] + m[1, 3] * c[0]) * inv,
            (-m[0, 0] * c[4] + m[0, 1] * c[2] - m[0, 3] * c[0]) * inv,
            (m[3, 0] * s[4] - m[3, 1] * s[2] + m[3, 3] * s[0]) * inv,
            (-m[2, 0] * s[4] + m[2, 1] * s[2] - m[2, 3] * s[0]) * inv,
            (-m[1, 0] * c[3] + m[1, 1] * c[1] - m[1, 2] * c[0]) * inv,
            (m[0, 0] * c[3] - m[0, 1] * c[1] + m[0, 2] * c[0]) * inv,
            (-m[3, 0] * s[3] + m[3, 1] * s[1] - m[3, 2] * s[0]) * inv,
            (m[2, 0] * s[3] - m[2, 1] * s[1] + m[2, 2] * s[0]) * inv,
        )

    @func
    def _hypot(a: S, b: S) -> S:
        # sqrt(a^2 + b^2) without overflow or underflow in the squares.
        big = wp.max(wp.abs(a), wp.abs(b))
        if big == S(0.0):
            return S(0.0)
        x = a / big
        y = b / big
        return big * wp.sqrt(x * x + y * y)

    @func
    def _givens(a: S, b: S) -> V2:
        # (c, s) of the rotation taking (a, b) to (hypot(a, b), 0).
        r = _hypot(a, b)
        if r == S(0.0):
            return V2(S(1.0), S(0.0))
        return V2(a / r, b / r)

    @func
    def _rotation(cs: V2, p: int, q: int) -> M33:
        # The identity with [[c, s], [-s, c]] in rows/columns p, q (p < q).
        g = wp.identity(n=3, dtype=S)
        g[p, p] = cs[0]
        g[p, q] = cs[1]
        g[q, p] = -cs[1]
        g[q, q] = cs[0]
        return g

    @func
    def qr3(a: M33):
        """QR of a 3x3 matrix by Givens rotations: ``(Q, R)``, ``det(Q) = +1``."""
        r = a
        q = wp.identity(n=3, dtype=S)
        g = _rotation(_givens(r[0, 0], r[1, 0]), 0, 1)
        r = g @ r
        q = q @ wp.transpose(g)
        g = _rotation(_givens(r[0, 0], r[2, 0]), 0, 2)
        r = g @ r
        q = q @ wp.transpose(g)
        g = _rotation(_givens(r[1, 1], r[2, 1]), 1, 2)
        r = g @ r
        q = q @ wp.transpose(g)
        # The rotations zeroed the lower triangle up to rounding: make it exact.
        r[1, 0] = S(0.0)
        r[2, 0] = S(0.0)
        r[2, 1] = S(0.0)
        return q, r

    @func
    def _jacobi(s: M33, p: int, q: int) -> M33:
        # The rotation (columns p, q) that zeroes s[p, q] of the symmetric s.
        apq = s[p, q]
        if apq == S(0.0):
            return wp.identity(n=3, dtype=S)
        theta = (s[q, q] - s[p, p]) / (S(2.0) * apq)
        t = wp.sign(theta) / (wp.abs(theta) + wp.sqrt(theta * theta + S(1.0)))
        c = S(1.0) / wp.sqrt(t * t + S(1.0))
        j = wp.identity(n=3, dtype=S)
        j[p, p] = c
        j[q, q] = c
        j[p, q] = t * c
        j[q, p] = -t * c
        return j

    @func
    def eig3(a: M33):
        """Eigendecomposition of a symmetric 3x3 matrix (cyclic Jacobi): ``(Q, d)``."""
        s = a
        q = wp.identity(n=3, dtype=S)
        for _sweep in range(sweeps):
            j = _jacobi(s, 0, 1)
            s = wp.transpose(j) @ s @ j
            q = q @ j
            j = _jacobi(s, 0, 2)
            s = wp.transpose(j) @ s @ j
            q = q @ j
            j = _jacobi(s, 1, 2)
            s = wp.transpose(j) @ s @ j
            q = q @ j
        return q, V3(s[0, 0], s[1, 1], s[2, 2])

    @func
    def _sort_desc(vt: M33, d: V3) -> M33:
        # Rows of vt (eigenvectors) ordered by decreasing d; a swap negates one row so
        # the determinant stays +1.
        r0 = vt[0]
        r1 = vt[1]
        r2 = vt[2]
        e0 = d[0]
        e1 = d[1]
        e2 = d[2]
        if e0 < e1:
            r0, r1 = r1, -r0
            e0, e1 = e1, e0
        if e0 < e2:
            r0, r2 = r2, -r0
            e0, e2 = e2, e0
        if e1 < e2:
            r1, r2 = r2, -r1
        return M33(r0, r1, r2)

    @func
    def svd3(a: M33):
        """SVD of a 3x3 matrix: ``(U, sigma, V)`` with ``A = U diag(sigma) V^T``."""
        vecs, d = eig3(wp.transpose(a) @ a)
        v = wp.transpose(_sort_desc(wp.transpose(vecs), d))
        u, r = qr3(a @ v)
        return u, V3(r[0, 0], r[1, 1], r[2, 2]), v

    @func
    def svd2(a: M22):
        """SVD of a 2x2 matrix: ``(U, sigma, V)``, ``sigma >= 0`` decreasing."""
        # One Jacobi rotation diagonalizes A^T A exactly.
        ata = wp.transpose(a) @ a
        c = S(1.0)
        s = S(0.0)
        if ata[0, 1] != S(0.0):
            theta = (ata[1, 1] - ata[0, 0]) / (S(2.0) * ata[0, 1])
            t = wp.sign(theta) / (wp.abs(theta) + wp.sqrt(theta * theta + S(1.0)))
            c = S(1.0) / wp.sqrt(t * t + S(1.0))
            s = t * c
        v = M22(c, s, -s, c)
        e0 = c * c * ata[0, 0] - S(2.0) * c * s * ata[0, 1] + s * s * ata[1, 1]
        e1 = s * s * ata[0, 0] + S(2.0) * c * s * ata[0, 1] + c * c * ata[1, 1]
        if e0 < e1:
            v = M22(v[0, 1], -v[0, 0], v[1, 1], -v[1, 0])
        b = a @ v
        g = _givens(b[0, 0], b[1, 0])
        u = M22(g[0], -g[1], g[1], g[0])
        r = wp.transpose(u) @ b
        sigma = V2(r[0, 0], r[1, 1])
        if sigma[1] < S(0.0):
            sigma[1] = -sigma[1]
            u = M22(u[0, 0], -u[0, 1], u[1, 0], -u[1, 1])
        return u, sigma, v


for _S in (kt.float16, kt.float32, kt.float64):
    _define_for(_S, kt.vector(2, _S), kt.vector(3, _S), kt.matrix((2, 2), _S),
                kt.matrix((3, 3), _S), kt.matrix((4, 4), _S), _SWEEPS[kt.type_of(_S).bits])
