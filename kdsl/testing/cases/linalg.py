"""Conformance cases: vector and matrix builtins and decompositions (issue 5).

Each runs over float32 and float64. Decompositions are checked through what is
unique about them (singular values, reconstruction ``A``, orthogonality, the
determinants of the factors), since singular vectors are determined only up to
sign. Singular matrices (determinant exactly 0) invert to the zero matrix.
"""

import numpy as np

import kdsl as wp
from kdsl.testing.case import Case, f64, uniform
from kdsl.testing.cases.dtype_rows import FLOAT_TYPES

N = 24
#: Decompositions iterate: compare float32 results a little more loosely.
_ITER_TOL = {np.float32: (2e-4, 2e-4), np.float64: (1e-10, 1e-10)}


def _mats(rng, n, np_dtype, lo=-2.0, hi=2.0):
    return uniform(rng, (N, n, n), lo, hi, np_dtype)


# --- componentwise and reductions ------------------------------------------------------------


def _cw_kernel(vtype, mtype):
    @wp.kernel
    def cw(a: wp.array(dtype=vtype), b: wp.array(dtype=vtype), ma: wp.array(dtype=mtype),
           mb: wp.array(dtype=mtype), vmul: wp.array(dtype=vtype), vdiv: wp.array(dtype=vtype),
           mmul: wp.array(dtype=mtype), mdiv: wp.array(dtype=mtype)):  # fmt: skip
        i = wp.tid()
        vmul[i] = wp.cw_mul(a[i], b[i])
        vdiv[i] = wp.cw_div(a[i], b[i])
        mmul[i] = wp.cw_mul(ma[i], mb[i])
        mdiv[i] = wp.cw_div(ma[i], mb[i])

    return cw


def _cw_cases() -> list[Case]:
    out = []
    for tname, dtype, d, req in FLOAT_TYPES:
        vtype, mtype = wp.vector(3, dtype), wp.matrix((3, 3), dtype)

        def make(rng, d=d):
            b = uniform(rng, (N, 3), -3, 3, d)
            b[0] = [0.0, -0.0, np.inf]  # x/0 is +-inf, 0/0 NaN
            a = uniform(rng, (N, 3), -3, 3, d)
            a[0] = [1.0, 0.0, 2.0]
            z3, z33 = np.zeros((N, 3), d), np.zeros((N, 3, 3), d)
            return {"a": a, "b": b, "ma": _mats(rng, 3, d), "mb": _mats(rng, 3, d, 0.5, 2.0),
                    "vmul": z3, "vdiv": z3.copy(), "mmul": z33, "mdiv": z33.copy()}  # fmt: skip

        def reference(ins):
            with np.errstate(all="ignore"):
                return {"vmul": f64(ins["a"]) * f64(ins["b"]), "vdiv": f64(ins["a"]) / f64(ins["b"]),
                        "mmul": f64(ins["ma"]) * f64(ins["mb"]),
                        "mdiv": f64(ins["ma"]) / f64(ins["mb"])}  # fmt: skip

        out.append(Case(f"la_cw_{tname}", _cw_kernel(vtype, mtype), N, make, reference,
                        ("vmul", "vdiv", "mmul", "mdiv"), requires=req))  # fmt: skip
    return out


@wp.kernel
def cw_int(a: wp.array(dtype=wp.vec3i), b: wp.array(dtype=wp.vec3i), p: wp.array(dtype=wp.vec3i),
           q: wp.array(dtype=wp.vec3i)):  # fmt: skip
    i = wp.tid()
    p[i] = wp.cw_mul(a[i], b[i])
    q[i] = wp.cw_div(a[i], b[i])


def _cw_int_inputs(rng):
    a = rng.integers(-100, 100, (N, 3)).astype(np.int32)
    b = rng.integers(-5, 5, (N, 3)).astype(np.int32)
    a[0], b[0] = [7, -7, -(2**31)], [0, 2, -1]  # x / 0 = 0, INT_MIN / -1 wraps
    return {"a": a, "b": b, "p": np.zeros((N, 3), np.int32), "q": np.zeros((N, 3), np.int32)}


def _cw_int_ref(ins):
    a, b = ins["a"].astype(np.int64), ins["b"].astype(np.int64)
    safe = np.where(b == 0, 1, b)
    q = np.where(b == 0, 0, np.trunc(a / safe)).astype(np.int64)
    return {"p": (a * b).astype(np.int32), "q": q.astype(np.int64).astype(np.int32)}


def _reduce_kernel(dtype):
    v4, m33 = wp.vector(4, dtype), wp.matrix((3, 3), dtype)

    @wp.kernel
    def reductions(v: wp.array(dtype=v4), m: wp.array(dtype=m33), n: wp.array(dtype=m33),
                   delta: wp.array(dtype=dtype), out: wp.array2d(dtype=dtype),
                   idx: wp.array2d(dtype=wp.uint32), unit: wp.array(dtype=v4)):  # fmt: skip
        i = wp.tid()
        out[i, 0] = wp.ddot(m[i], n[i])
        out[i, 1] = wp.trace(m[i])
        out[i, 2] = wp.norm_l1(v[i])
        out[i, 3] = wp.norm_l2(v[i])
        out[i, 4] = wp.norm_huber(v[i], delta[i])
        out[i, 5] = wp.norm_pseudo_huber(v[i], delta[i])
        idx[i, 0] = wp.argmin(v[i])
        idx[i, 1] = wp.argmax(v[i])
        unit[i] = wp.smooth_normalize(v[i], delta[i])

    return reductions


def _reduce_cases() -> list[Case]:
    out = []
    for tname, dtype, d, req in FLOAT_TYPES:

        def make(rng, d=d):
            v = uniform(rng, (N, 4), -3, 3, d)
            v[0] = [1.0, 1.0, 1.0, 1.0]  # ties: the first index
            v[1] = [np.nan, 2.0, -1.0, np.nan]  # NaN skipped
            v[2] = np.nan  # all NaN: index 0
            v[3] = 0.0
            v[4] = [0.1, -0.2, 0.1, 0.05]  # |v| below delta: the quadratic branch
            delta = uniform(rng, N, 0.5, 2.0, d)
            return {"v": v, "m": _mats(rng, 3, d), "n": _mats(rng, 3, d), "delta": delta,
                    "out": np.zeros((N, 6), d), "idx": np.zeros((N, 2), np.uint32),
                    "unit": np.zeros((N, 4), d)}  # fmt: skip

        def reference(ins):
            v, m, n, dl = f64(ins["v"]), f64(ins["m"]), f64(ins["n"]), f64(ins["delta"])
            norm = np.sqrt(np.sum(v * v, axis=1))
            huber = np.where(norm <= dl, 0.5 * norm**2, dl * (norm - 0.5 * dl))
            huber = np.where(np.isnan(norm), np.nan, huber)
            pseudo = dl * np.sqrt(1.0 + norm**2 / dl**2)
            filled_lo = np.where(np.isnan(v), np.inf, v)
            filled_hi = np.where(np.isnan(v), -np.inf, v)
            cols = [np.sum(m * n, axis=(1, 2)), np.trace(m, axis1=1, axis2=2),
                    np.sum(np.abs(v), axis=1), norm, huber, pseudo]  # fmt: skip
            return {"out": np.stack(cols, axis=1),
                    "idx": np.stack([np.argmin(filled_lo, 1), np.argmax(filled_hi, 1)], 1),
                    "unit": v / pseudo[:, None]}  # fmt: skip

        out.append(Case(f"la_reductions_{tname}", _reduce_kernel(dtype), N, make, reference,
                        ("out", "idx", "unit"), requires=req))  # fmt: skip
    return out


# --- structural builders --------------------------------------------------------------------


def _build_kernel(dtype):
    v3, m33 = wp.vector(3, dtype), wp.matrix((3, 3), dtype)
    m23 = wp.matrix((2, 3), dtype)

    @wp.kernel
    def builders(v: wp.array(dtype=v3), w: wp.array(dtype=v3), m: wp.array(dtype=m33),
                 diag: wp.array(dtype=m33), get_diag: wp.array(dtype=v3),
                 skew: wp.array(dtype=m33), skew_check: wp.array(dtype=v3),
                 ident: wp.array(dtype=m33), rows: wp.array(dtype=m33),
                 cols: wp.array(dtype=m33), ctor: wp.array(dtype=m23),
                 vec: wp.array(dtype=v3)):  # fmt: skip
        i = wp.tid()
        diag[i] = wp.diag(v[i])
        get_diag[i] = wp.get_diag(m[i])
        skew[i] = wp.skew(v[i])
        skew_check[i] = wp.skew(v[i]) @ w[i] - wp.cross(v[i], w[i])
        ident[i] = wp.identity(n=3, dtype=dtype) * v[i][0] + wp.identity(3, dtype)
        rows[i] = wp.matrix_from_rows(v[i], w[i], v[i] + w[i])
        cols[i] = wp.matrix_from_cols(v[i], w[i], v[i] + w[i])
        x = v[i]
        ctor[i] = wp.matrix(x[0], x[1], x[2], w[i][0], w[i][1], w[i][2], shape=(2, 3),
                            dtype=dtype) + wp.matrix(shape=(2, 3), dtype=dtype)  # fmt: skip
        vec[i] = wp.vector(x[2], x[1], x[0], dtype=dtype) + wp.vector(length=3, dtype=dtype)

    return builders


def _build_cases() -> list[Case]:
    out = []
    for tname, dtype, d, req in FLOAT_TYPES:

        def make(rng, d=d):
            z = {k: np.zeros((N, 3, 3), d) for k in ("diag", "skew", "ident", "rows", "cols")}
            return {"v": uniform(rng, (N, 3), -3, 3, d), "w": uniform(rng, (N, 3), -3, 3, d),
                    "m": _mats(rng, 3, d), "get_diag": np.zeros((N, 3), d),
                    "skew_check": np.zeros((N, 3), d), "ctor": np.zeros((N, 2, 3), d),
                    "vec": np.zeros((N, 3), d), **z}  # fmt: skip

        def reference(ins):
            v, w, m = f64(ins["v"]), f64(ins["w"]), f64(ins["m"])
            x, y, z = v[:, 0], v[:, 1], v[:, 2]
            o = np.zeros_like(x)
            skew = np.stack([o, -z, y, z, o, -x, -y, x, o], 1).reshape(N, 3, 3)
            eye = np.eye(3)[None]
            return {"diag": eye * v[:, None, :], "get_diag": np.diagonal(m, axis1=1, axis2=2),
                    "skew": skew, "skew_check": np.zeros((N, 3)),
                    "ident": eye * (x[:, None, None] + 1.0),
                    "rows": np.stack([v, w, v + w], 1), "cols": np.stack([v, w, v + w], 2),
                    "ctor": np.stack([v, w], 1), "vec": v[:, ::-1]}  # fmt: skip

        out.append(Case(f"la_builders_{tname}", _build_kernel(dtype), N, make, reference,
                        ("diag", "get_diag", "skew", "skew_check", "ident", "rows", "cols",
                         "ctor", "vec"), requires=req, tol=(1e-5, 1e-5) if d == np.float32
                        else None))  # fmt: skip
    return out


# --- determinant and inverse ---------------------------------------------------------------


def _det_inv_kernel(mtype, dtype):
    @wp.kernel
    def det_inv(m: wp.array(dtype=mtype), det: wp.array(dtype=dtype),
                inv: wp.array(dtype=mtype)):  # fmt: skip
        i = wp.tid()
        det[i] = wp.determinant(m[i])
        inv[i] = wp.inverse(m[i])

    return det_inv


def _det_inv_cases() -> list[Case]:
    out = []
    for tname, dtype, d, req in FLOAT_TYPES:
        for n in (2, 3, 4):

            def make(rng, n=n, d=d):
                m = _mats(rng, n, d) + (2.5 * np.eye(n)).astype(d)  # well conditioned
                m[0] = 0.0  # singular: zero inverse
                m[1] = np.arange(n * n).reshape(n, n)  # rank 2: determinant exactly 0
                m[2] = np.diag(np.arange(1, n + 1))
                return {"m": m, "det": np.zeros(N, d), "inv": np.zeros((N, n, n), d)}

            def reference(ins):
                m = f64(ins["m"])
                det = np.linalg.det(m)
                singular = np.abs(det) < 1e-9
                safe = np.where(singular[:, None, None], np.eye(m.shape[1]), m)
                inv = np.where(singular[:, None, None], 0.0, np.linalg.inv(safe))
                return {"det": np.where(singular, 0.0, det), "inv": inv}

            tol = (2e-5, 2e-5) if d == np.float32 else (1e-11, 1e-11)
            out.append(Case(f"la_det_inv{n}_{tname}", _det_inv_kernel(wp.matrix((n, n), dtype),
                            dtype), N, make, reference, ("det", "inv"), requires=req,
                            tol=tol))  # fmt: skip
    return out


# --- decompositions ----------------------------------------------------------------------------


def _svd3_kernel(dtype):
    m33, v3 = wp.matrix((3, 3), dtype), wp.vector(3, dtype)

    @wp.kernel
    def svd3(a: wp.array(dtype=m33), sigma: wp.array(dtype=v3), recon: wp.array(dtype=m33),
             utu: wp.array(dtype=m33), vtv: wp.array(dtype=m33), dets: wp.array(dtype=wp.vector(2, dtype))):  # fmt: skip
        i = wp.tid()
        U, s, V = wp.svd3(a[i])
        sigma[i] = s
        recon[i] = U @ wp.diag(s) @ wp.transpose(V)
        utu[i] = wp.transpose(U) @ U
        vtv[i] = wp.transpose(V) @ V
        dets[i] = wp.vector(wp.determinant(U), wp.determinant(V), dtype=dtype)

    return svd3


def _signed_sigma(a: np.ndarray) -> np.ndarray:
    s = np.linalg.svd(a, compute_uv=False)
    s[:, 2] *= np.sign(np.linalg.det(a))
    return s


def _decomp_inputs(rng, d, sym=False):
    a = _mats(rng, 3, d)
    a[0] = np.eye(3)
    a[1] = np.diag([3.0, -2.0, 0.5])
    a[2] = 0.0
    a[3] = [[1, 2, 3], [2, 4, 6], [1, 1, 1]]  # rank 2
    if sym:
        a = a + np.transpose(a, (0, 2, 1))
    return a.astype(d)


def _svd3_cases() -> list[Case]:
    out = []
    for tname, dtype, d, req in FLOAT_TYPES:

        def make(rng, d=d):
            z = np.zeros((N, 3, 3), d)
            return {"a": _decomp_inputs(rng, d), "sigma": np.zeros((N, 3), d), "recon": z,
                    "utu": z.copy(), "vtv": z.copy(), "dets": np.zeros((N, 2), d)}

        def reference(ins):
            a = f64(ins["a"])
            eye = np.broadcast_to(np.eye(3), (N, 3, 3))
            return {"sigma": _signed_sigma(a), "recon": a, "utu": eye, "vtv": eye,
                    "dets": np.ones((N, 2))}

        out.append(Case(f"la_svd3_{tname}", _svd3_kernel(dtype), N, make, reference,
                        ("sigma", "recon", "utu", "vtv", "dets"), requires=req,
                        tol=_ITER_TOL[d]))  # fmt: skip
    return out


def _svd2_kernel(dtype):
    m22, v2 = wp.matrix((2, 2), dtype), wp.vector(2, dtype)

    @wp.kernel
    def svd2(a: wp.array(dtype=m22), sigma: wp.array(dtype=v2), recon: wp.array(dtype=m22),
             utu: wp.array(dtype=m22), vtv: wp.array(dtype=m22)):  # fmt: skip
        i = wp.tid()
        U, s, V = wp.svd2(a[i])
        sigma[i] = s
        recon[i] = U @ wp.diag(s) @ wp.transpose(V)
        utu[i] = wp.transpose(U) @ U
        vtv[i] = wp.transpose(V) @ V

    return svd2


def _svd2_cases() -> list[Case]:
    out = []
    for tname, dtype, d, req in FLOAT_TYPES:

        def make(rng, d=d):
            a = _mats(rng, 2, d)
            a[0], a[1], a[2] = np.eye(2), 0.0, [[1.0, 2.0], [2.0, 4.0]]
            a[3] = [[3.0, 0.0], [4.0, 5.0]]
            z = np.zeros((N, 2, 2), d)
            return {"a": a, "sigma": np.zeros((N, 2), d), "recon": z, "utu": z.copy(),
                    "vtv": z.copy()}  # fmt: skip

        def reference(ins):
            a = f64(ins["a"])
            eye = np.broadcast_to(np.eye(2), (N, 2, 2))
            return {"sigma": np.linalg.svd(a, compute_uv=False), "recon": a, "utu": eye,
                    "vtv": eye}  # fmt: skip

        out.append(Case(f"la_svd2_{tname}", _svd2_kernel(dtype), N, make, reference,
                        ("sigma", "recon", "utu", "vtv"), requires=req,
                        tol=_ITER_TOL[d]))  # fmt: skip
    return out


def _qr3_kernel(dtype):
    m33 = wp.matrix((3, 3), dtype)

    @wp.kernel
    def qr3(a: wp.array(dtype=m33), recon: wp.array(dtype=m33), qtq: wp.array(dtype=m33),
            lower: wp.array(dtype=wp.vector(3, dtype)), diag_det: wp.array(dtype=wp.vector(3, dtype))):  # fmt: skip
        i = wp.tid()
        Q, R = wp.qr3(a[i])
        recon[i] = Q @ R
        qtq[i] = wp.transpose(Q) @ Q
        lower[i] = wp.vector(R[1, 0], R[2, 0], R[2, 1], dtype=dtype)
        diag_det[i] = wp.vector(wp.min(R[0, 0], dtype(0.0)), wp.min(R[1, 1], dtype(0.0)),
                                wp.determinant(Q), dtype=dtype)  # fmt: skip

    return qr3


def _qr3_cases() -> list[Case]:
    out = []
    for tname, dtype, d, req in FLOAT_TYPES:

        def make(rng, d=d):
            z = np.zeros((N, 3, 3), d)
            return {"a": _decomp_inputs(rng, d), "recon": z, "qtq": z.copy(),
                    "lower": np.zeros((N, 3), d), "diag_det": np.zeros((N, 3), d)}  # fmt: skip

        def reference(ins):
            a = f64(ins["a"])
            dd = np.zeros((N, 3))
            dd[:, 2] = 1.0  # R[0,0], R[1,1] >= 0 and det(Q) = +1
            return {"recon": a, "qtq": np.broadcast_to(np.eye(3), (N, 3, 3)),
                    "lower": np.zeros((N, 3)), "diag_det": dd}  # fmt: skip

        out.append(Case(f"la_qr3_{tname}", _qr3_kernel(dtype), N, make, reference,
                        ("recon", "qtq", "lower", "diag_det"), requires=req,
                        tol=_ITER_TOL[d]))  # fmt: skip
    return out


def _eig3_kernel(dtype):
    m33, v3 = wp.matrix((3, 3), dtype), wp.vector(3, dtype)

    @wp.kernel
    def eig3(a: wp.array(dtype=m33), recon: wp.array(dtype=m33), qtq: wp.array(dtype=m33),
             sorted_d: wp.array(dtype=v3), det_q: wp.array(dtype=dtype)):  # fmt: skip
        i = wp.tid()
        Q, d = wp.eig3(a[i])
        recon[i] = Q @ wp.diag(d) @ wp.transpose(Q)
        qtq[i] = wp.transpose(Q) @ Q
        lo = wp.min(d)
        hi = wp.max(d)
        sorted_d[i] = wp.vector(lo, d[0] + d[1] + d[2] - lo - hi, hi, dtype=dtype)
        det_q[i] = wp.determinant(Q)

    return eig3


def _eig3_cases() -> list[Case]:
    out = []
    for tname, dtype, d, req in FLOAT_TYPES:

        def make(rng, d=d):
            z = np.zeros((N, 3, 3), d)
            return {"a": _decomp_inputs(rng, d, sym=True), "recon": z, "qtq": z.copy(),
                    "sorted_d": np.zeros((N, 3), d), "det_q": np.zeros(N, d)}  # fmt: skip

        def reference(ins):
            a = f64(ins["a"])
            return {"recon": a, "qtq": np.broadcast_to(np.eye(3), (N, 3, 3)),
                    "sorted_d": np.linalg.eigvalsh(a), "det_q": np.ones(N)}  # fmt: skip

        out.append(Case(f"la_eig3_{tname}", _eig3_kernel(dtype), N, make, reference,
                        ("recon", "qtq", "sorted_d", "det_q"), requires=req,
                        tol=_ITER_TOL[d]))  # fmt: skip
    return out


def _rotations(rng, n: int) -> np.ndarray:
    """``n`` random 3x3 rotations (determinant +1) from QR of Gaussian matrices."""
    q, r = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    q = q * np.sign(np.diagonal(r, axis1=1, axis2=2))[:, None, :]
    q[np.linalg.det(q) < 0, :, 0] *= -1.0
    return q


def _repeated_cases() -> list[Case]:
    """eig3 and svd3 where eigen/singular values repeat (their vectors are not unique)."""
    out = []
    for tname, dtype, d, req in FLOAT_TYPES:

        def make_eig(rng, d=d):
            r = _rotations(rng, N)
            vals = np.tile([2.0, 2.0, 5.0], (N, 1))
            vals[::3] = [1.0, 1.0, 1.0]
            vals[1::3] = [-3.0, 0.0, 0.0]
            a = r @ (vals[:, :, None] * np.transpose(r, (0, 2, 1)))
            z = np.zeros((N, 3, 3), d)
            return {"a": a.astype(d), "recon": z, "qtq": z.copy(),
                    "sorted_d": np.zeros((N, 3), d), "det_q": np.zeros(N, d)}  # fmt: skip

        def ref_eig(ins):
            a = f64(ins["a"])
            return {"recon": a, "qtq": np.broadcast_to(np.eye(3), (N, 3, 3)),
                    "sorted_d": np.linalg.eigvalsh(a), "det_q": np.ones(N)}  # fmt: skip

        out.append(Case(f"la_eig3_repeated_{tname}", _eig3_kernel(dtype), N, make_eig, ref_eig,
                        ("recon", "qtq", "sorted_d", "det_q"), requires=req,
                        tol=_ITER_TOL[d]))  # fmt: skip

        def make_svd(rng, d=d):
            sig = np.tile([3.0, 3.0, 1.0], (N, 1))
            sig[::2] = [2.0, 0.5, 0.5]
            sig[::5] = [1.0, 0.0, 0.0]
            a = _rotations(rng, N) @ (sig[:, :, None] * _rotations(rng, N))
            z = np.zeros((N, 3, 3), d)
            return {"a": a.astype(d), "sigma": np.zeros((N, 3), d), "recon": z,
                    "utu": z.copy(), "vtv": z.copy(), "dets": np.zeros((N, 2), d)}  # fmt: skip

        def ref_svd(ins):
            a = f64(ins["a"])
            eye = np.broadcast_to(np.eye(3), (N, 3, 3))
            sigma = np.linalg.svd(a, compute_uv=False)  # det(a) >= 0 here
            return {"sigma": sigma, "recon": a, "utu": eye, "vtv": eye, "dets": np.ones((N, 2))}

        out.append(Case(f"la_svd3_repeated_{tname}", _svd3_kernel(dtype), N, make_svd, ref_svd,
                        ("sigma", "recon", "utu", "vtv", "dets"), requires=req,
                        tol=_ITER_TOL[d]))  # fmt: skip
    return out


def _rect_kernel(dtype):
    v4 = wp.vector(4, dtype)
    m24, m42 = wp.matrix((2, 4), dtype), wp.matrix((4, 2), dtype)

    @wp.kernel
    def rect(a: wp.array(dtype=v4), b: wp.array(dtype=v4), rows: wp.array(dtype=m24),
             cols: wp.array(dtype=m42), dd: wp.array(dtype=dtype)):  # fmt: skip
        i = wp.tid()
        r = wp.matrix_from_rows(a[i], b[i])
        c = wp.matrix_from_cols(a[i], b[i])
        rows[i] = r
        cols[i] = c
        dd[i] = wp.ddot(r, wp.transpose(c))

    return rect


def _rect_cases() -> list[Case]:
    out = []
    for tname, dtype, d, req in FLOAT_TYPES:

        def make(rng, d=d):
            return {"a": uniform(rng, (N, 4), -3, 3, d), "b": uniform(rng, (N, 4), -3, 3, d),
                    "rows": np.zeros((N, 2, 4), d), "cols": np.zeros((N, 4, 2), d),
                    "dd": np.zeros(N, d)}  # fmt: skip

        def reference(ins):
            a, b = f64(ins["a"]), f64(ins["b"])
            return {"rows": np.stack([a, b], 1), "cols": np.stack([a, b], 2),
                    "dd": np.sum(a * a + b * b, axis=1)}  # fmt: skip

        out.append(Case(f"la_rect_{tname}", _rect_kernel(dtype), N, make, reference,
                        ("rows", "cols", "dd"), requires=req))  # fmt: skip
    return out


@wp.kernel
def arg_int(v: wp.array(dtype=wp.vec4i), u: wp.array(dtype=wp.vec3ub),
            idx: wp.array2d(dtype=wp.uint32), ext: wp.array2d(dtype=wp.int32)):  # fmt: skip
    i = wp.tid()
    idx[i, 0] = wp.argmin(v[i])
    idx[i, 1] = wp.argmax(v[i])
    idx[i, 2] = wp.argmin(u[i])
    idx[i, 3] = wp.argmax(u[i])
    ext[i, 0] = wp.min(v[i])
    ext[i, 1] = wp.max(v[i])


def _arg_int_inputs(rng):
    v = rng.integers(-3, 3, (N, 4)).astype(np.int32)  # many ties
    v[0] = [-(2**31), 2**31 - 1, -(2**31), 2**31 - 1]
    return {"v": v, "u": rng.integers(0, 4, (N, 3)).astype(np.uint8),
            "idx": np.zeros((N, 4), np.uint32), "ext": np.zeros((N, 2), np.int32)}  # fmt: skip


def _arg_int_ref(ins):
    v, u = ins["v"], ins["u"]
    idx = np.stack([np.argmin(v, 1), np.argmax(v, 1), np.argmin(u, 1), np.argmax(u, 1)], 1)
    return {"idx": idx, "ext": np.stack([v.min(1), v.max(1)], 1)}


@wp.kernel
def identities(s: wp.array(dtype=wp.int32), i2: wp.array(dtype=wp.matrix((2, 2), wp.int32)),
               h3: wp.array(dtype=wp.mat33h), d4: wp.array(dtype=wp.mat44d)):  # fmt: skip
    k = wp.tid()
    i2[k] = wp.identity(2, wp.int32) * s[k]
    h3[k] = wp.identity(n=3, dtype=wp.float16) * wp.float16(s[k])
    d4[k] = wp.identity(dtype=wp.float64, n=4) * wp.float64(s[k])


def _identities_inputs(rng):
    return {"s": np.arange(N, dtype=np.int32) - 5, "i2": np.zeros((N, 2, 2), np.int32),
            "h3": np.zeros((N, 3, 3), np.float16), "d4": np.zeros((N, 4, 4))}  # fmt: skip


def _identities_ref(ins):
    s = ins["s"].astype(np.float64)[:, None, None]
    return {"i2": (np.eye(2) * s).astype(np.int32), "h3": np.eye(3) * s, "d4": np.eye(4) * s}


def _half_det_inv_cases() -> list[Case]:
    out = []
    for n in (2, 3, 4):

        def make(rng, n=n):
            m = (_mats(rng, n, np.float64, -1, 1) + 3.0 * np.eye(n)).astype(np.float16)
            m[0] = 0.0
            return {"m": m, "det": np.zeros(N, np.float16),
                    "inv": np.zeros((N, n, n), np.float16)}  # fmt: skip

        def reference(ins):
            m = f64(ins["m"])
            det = np.linalg.det(m)
            safe = np.where((det == 0)[:, None, None], np.eye(m.shape[1]), m)
            inv = np.where((det == 0)[:, None, None], 0.0, np.linalg.inv(safe))
            return {"det": det, "inv": inv}

        out.append(Case(f"la_det_inv{n}_f16", _det_inv_kernel(wp.matrix((n, n), wp.float16),
                        wp.float16), N, make, reference, ("det", "inv"), requires=("fp16",),
                        tol=(2e-2, 2e-2)))  # fmt: skip
    return out


# --- typed vector variants --------------------------------------------------------------------

_VARIANTS = (("vec3b", wp.vec3b, np.int8), ("vec3ub", wp.vec3ub, np.uint8),
             ("vec3s", wp.vec3s, np.int16), ("vec3us", wp.vec3us, np.uint16),
             ("vec3l", wp.vec3l, np.int64), ("vec3ul", wp.vec3ul, np.uint64),
             ("vec4h", wp.vec4h, np.float16))  # fmt: skip


def _variant_kernel(vtype):
    @wp.kernel
    def variant(a: wp.array(dtype=vtype), b: wp.array(dtype=vtype), s: wp.array(dtype=vtype),
                p: wp.array(dtype=vtype), m: wp.array(dtype=vtype)):  # fmt: skip
        i = wp.tid()
        s[i] = a[i] + b[i]
        p[i] = wp.cw_mul(a[i], b[i])
        m[i] = wp.max(a[i], b[i])

    return variant


def _variant_cases() -> list[Case]:
    out = []
    for name, vtype, d in _VARIANTS:
        n = 4 if d == np.float16 else 3

        def make(rng, d=d, n=n):
            if d == np.float16:
                a, b = uniform(rng, (N, n), -4, 4, d), uniform(rng, (N, n), -4, 4, d)
            else:
                info = np.iinfo(d)
                a = rng.integers(info.min, info.max, (N, n), dtype=d, endpoint=True)
                b = rng.integers(info.min, info.max, (N, n), dtype=d, endpoint=True)
            z = np.zeros((N, n), d)
            return {"a": a, "b": b, "s": z, "p": z.copy(), "m": z.copy()}

        def reference(ins):
            a, b = ins["a"], ins["b"]
            with np.errstate(all="ignore"):  # integers wrap
                return {"s": a + b, "p": a * b, "m": np.maximum(a, b)}

        out.append(Case(f"la_variant_{name}", _variant_kernel(vtype), N, make, reference,
                        ("s", "p", "m")))  # fmt: skip
    return out


CASES: list[Case] = [
    *_cw_cases(),
    Case("la_cw_int", cw_int, N, _cw_int_inputs, _cw_int_ref, ("p", "q")),
    *_reduce_cases(),
    *_build_cases(),
    *_det_inv_cases(),
    *_svd3_cases(),
    *_svd2_cases(),
    *_qr3_cases(),
    *_eig3_cases(),
    *_variant_cases(),
    *_repeated_cases(),
    *_rect_cases(),
    *_half_det_inv_cases(),
    Case("la_arg_int", arg_int, N, _arg_int_inputs, _arg_int_ref, ("idx", "ext")),
    Case("la_identities", identities, N, _identities_inputs, _identities_ref, ("i2", "h3", "d4"),
         requires=("fp16", "fp64")),
]
