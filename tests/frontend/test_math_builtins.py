"""The scalar, vector and matrix math builtins: Warp's semantics, kdsl's documented
differences, typed variants, and located errors for wrong argument types.

Numerical coverage over many inputs lives in the conformance cases
(``kdsl/testing/cases/scalar_math.py`` and ``linalg.py``); this file checks the
rules against Warp 1.19 on CPU directly (skipped without warp) and the error paths.
"""
# ruff: noqa: SIM300, RUF059


import numpy as np
import pytest

import kdsl as wp
from kdsl.testing.cases.scalar_math import ref_erfcinv
from tests.frontend.located_errors import expect_error_at_marker
from tests.warp_peer import import_warp_cpu

F = wp.array(dtype=float)


def _run(kernel, *arrays, backend="cpu"):
    args = [wp.from_numpy(np.array(a, copy=True), dtype=d) for a, d in arrays]
    wp.launch(kernel, dim=1, inputs=args, backend=backend)
    return [a.numpy() for a in args]


# --- semantics vs Warp -------------------------------------------------------------------

_SCALAR_INPUTS = np.array([np.nan, -np.inf, -1.5, -1.0, -0.5, -0.0, 0.0, 1e-45, 0.5, 0.7, 1.0,
                           1.5, 2.0, np.inf, 3.4e38, -2.5], np.float32)  # fmt: skip
_SCALAR_OPS = ["step", "nonzero", "frac", "sign", "ss01", "ss10", "lerp", "degrees", "radians",
               "erfinv", "erfcinv", "round", "rint", "abs", "clamp"]  # fmt: skip


def _scalar_kernel(lib):
    def body(x: lib.array(dtype=float), o: lib.array2d(dtype=float)):
        i = lib.tid()
        v = x[i]
        o[i, 0] = lib.step(v)
        o[i, 1] = lib.nonzero(v)
        o[i, 2] = lib.frac(v)
        o[i, 3] = lib.sign(v)
        o[i, 4] = lib.smoothstep(0.0, 1.0, v)
        o[i, 5] = lib.smoothstep(1.0, 0.0, v)
        o[i, 6] = lib.lerp(2.0, 4.0, v)
        o[i, 7] = lib.degrees(v)
        o[i, 8] = lib.radians(v)
        o[i, 9] = lib.erfinv(v)
        o[i, 10] = lib.erfcinv(v)
        o[i, 11] = lib.round(v)
        o[i, 12] = lib.rint(v)
        o[i, 13] = lib.abs(v)
        o[i, 14] = lib.clamp(v, -1.0, 1.0)

    return lib.kernel(body)


@pytest.fixture(scope="module")
def warp():
    return import_warp_cpu()


def _launch_both(warp, make, inputs, out_shape):
    """Run kernel ``make(lib)`` on kdsl (cpu) and Warp (cpu); return both outputs."""
    ours = make(wp)
    x = wp.from_numpy(inputs, dtype=wp.float32)
    o = wp.zeros(out_shape, dtype=wp.float32)
    wp.launch(ours, dim=len(inputs), inputs=[x, o], backend="cpu")
    theirs = make(warp)
    wx = warp.array(inputs, dtype=warp.float32, device="cpu")
    wo = warp.zeros(out_shape, dtype=warp.float32, device="cpu")
    warp.launch(theirs, dim=len(inputs), inputs=[wx, wo], device="cpu")
    return o.numpy(), wo.numpy()


@pytest.mark.slow
def test_scalar_math_matches_warp(warp):
    ours, theirs = _launch_both(warp, _scalar_kernel, _SCALAR_INPUTS, (16, len(_SCALAR_OPS)))
    nan_x = np.isnan(_SCALAR_INPUTS)
    for j, name in enumerate(_SCALAR_OPS):
        a, b = ours[:, j], theirs[:, j]
        if name == "clamp":  # kdsl's documented difference: NaN stays NaN (Warp: the bound)
            assert np.isnan(a[nan_x]).all() and (b[nan_x] == -1.0).all()
            a, b = a[~nan_x], b[~nan_x]
        if name in ("ss01", "ss10"):  # smoothstep of NaN: NaN in kdsl (through clamp), 0 in Warp
            assert np.isnan(a[nan_x]).all()
            a, b = a[~nan_x], b[~nan_x]
        if name == "erfinv":  # kdsl keeps erfinv(1e-45) ~ 1.2e-45 and erfinv(-0.0) = -0.0
            keep = (_SCALAR_INPUTS != np.float32(1e-45)) & ~((_SCALAR_INPUTS == 0) & np.signbit(
                _SCALAR_INPUTS))  # fmt: skip
            assert np.signbit(ours[5, j]) and ours[5, j] == 0
            a, b = a[keep], b[keep]
        if name == "erfcinv":  # erfcinv(1e-45) is ~10.05; Warp overflows to inf
            keep = _SCALAR_INPUTS != np.float32(1e-45)
            want = ref_erfcinv(np.array([np.float32(1e-45)], np.float64))[0]
            assert abs(ours[_SCALAR_INPUTS == np.float32(1e-45), j][0] - want) < 1e-5 * want
            a, b = a[keep], b[keep]
        np.testing.assert_allclose(a, b, rtol=2e-6, atol=1e-7, err_msg=name)
        np.testing.assert_array_equal(np.signbit(a[a == 0]), np.signbit(b[b == 0]), err_msg=name)


def _vector_kernel(lib):
    def body(x: lib.array(dtype=float), o: lib.array(dtype=float)):
        i = lib.tid()
        s = x[i]
        v = lib.vec4(3.0 * s, 1.0, 1.0, lib.sqrt(-1.0))
        w = lib.vec4(lib.sqrt(-1.0), 2.0, 5.0 * s, 5.0)
        m = lib.mat33(1.0, s, 3.0, 2.0, 4.0, 6.5, -1.0, 1.0, 2.0 * s)
        m4 = lib.mat44(2.0, s, 0.0, 1.0, 1.0, 3.0, 1.0, 0.0, 0.0, 1.0, 4.0, s, 1.0, 0.0, 2.0, 5.0)
        o[0] = lib.min(v)
        o[1] = lib.max(w)
        o[2] = float(lib.argmin(v))
        o[3] = float(lib.argmax(w))
        o[4] = lib.determinant(m)
        o[5] = lib.inverse(m)[1, 2]
        o[6] = lib.determinant(m4)
        o[7] = lib.inverse(m4)[3, 1]
        o[8] = lib.inverse(lib.mat22(1.0, 2.0, 2.0, 4.0))[0, 0]
        o[9] = lib.norm_huber(lib.vec2(3.0 * s, 4.0), 1.0)
        o[10] = lib.norm_pseudo_huber(lib.vec2(3.0, 4.0 * s), 2.0)
        o[11] = lib.smooth_normalize(lib.vec2(3.0 * s, 4.0), 2.0)[0]
        o[12] = lib.norm_l1(lib.vec3(-3.0, 4.0, s))
        o[13] = lib.ddot(m, m)
        o[14] = lib.trace(m)
        o[15] = lib.skew(lib.vec3(1.0, s, 3.0))[2, 1]
        o[16] = lib.identity(n=3, dtype=float)[1, 1] + lib.get_diag(m)[2]
        o[17] = lib.diag(lib.vec3(s, 2.0, 3.0))[0, 0]
        o[18] = lib.matrix_from_cols(lib.vec2(1.0, s), lib.vec2(3.0, 4.0))[1, 0]
        o[19] = lib.cw_div(lib.vec2(s, 0.0), lib.vec2(0.0, 0.0))[0]
        o[20] = lib.inverse(lib.mat33(1.0, 2.0, 3.0, 2.0, 4.0, 6.0, 1.0, 1.0, s))[0, 0]

    return lib.kernel(body)


@pytest.mark.slow
def test_vector_math_matches_warp(warp):
    ours, theirs = _launch_both(warp, _vector_kernel, np.array([0.75], np.float32), 21)
    np.testing.assert_allclose(ours, theirs, rtol=2e-6, atol=1e-6)


@pytest.mark.parametrize("backend", ["interp", "cpu"])
def test_svd3_convention(backend):
    @wp.kernel
    def k(a: wp.array(dtype=wp.mat33d), u: wp.array(dtype=wp.mat33d),
          s: wp.array(dtype=wp.vec3d), v: wp.array(dtype=wp.mat33d)):  # fmt: skip
        U, sigma, V = wp.svd3(a[0])
        u[0] = U
        s[0] = sigma
        v[0] = V

    a = np.array([[[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 10.0]]])  # det(a) = -3
    mat, vec = wp.mat33d, wp.vec3d
    _, u, s, v = _run(k, (a, mat), (np.zeros((1, 3, 3)), mat), (np.zeros((1, 3)), vec),
                      (np.zeros((1, 3, 3)), mat), backend=backend)  # fmt: skip
    u, s, v = u[0], s[0], v[0]
    assert s[0] >= s[1] >= abs(s[2]) and s[2] < 0  # sigma[2] carries the sign of det(a)
    np.testing.assert_allclose(np.linalg.det(u), 1.0, rtol=1e-12)
    np.testing.assert_allclose(np.linalg.det(v), 1.0, rtol=1e-12)
    np.testing.assert_allclose(u @ np.diag(s) @ v.T, a[0], atol=1e-12)


def test_keywords_and_in_kernel_constructors():
    @wp.kernel
    def k(o: wp.array(dtype=wp.mat22d), v: wp.array(dtype=wp.vec3h)):
        o[0] = wp.identity(dtype=wp.float64, n=2) + wp.matrix(1.0, 2.0, 3.0, 4.0, shape=(2, 2),
                                                             dtype=wp.float64)  # fmt: skip
        v[0] = wp.vector(wp.float16(1.0), wp.float16(2.0), wp.float16(3.0))

    _, out, vec = [None, *_run(k, (np.zeros((1, 2, 2)), wp.mat22d),
                               (np.zeros((1, 3), np.float16), wp.vec3h))]  # fmt: skip
    np.testing.assert_array_equal(out[0], [[2.0, 2.0], [3.0, 5.0]])
    np.testing.assert_array_equal(vec[0], [1.0, 2.0, 3.0])


def test_typed_variant_names():
    warp = pytest.importorskip("warp")

    for n in (2, 3, 4):
        for suffix, dtype in (("b", np.int8), ("ub", np.uint8), ("s", np.int16),
                              ("us", np.uint16), ("l", np.int64), ("ul", np.uint64),
                              ("h", np.float16), ("i", np.int32), ("ui", np.uint32)):  # fmt: skip
            name = f"vec{n}{suffix}"
            cls = getattr(wp, name)
            assert cls is wp.vector(n, wp.dtype_from_numpy(dtype)), name
            assert cls(1).dtype == dtype and cls(1).shape == (n,)
            assert hasattr(warp, name)
        assert getattr(wp, f"mat{n}{n}h") is wp.matrix((n, n), wp.float16)


@pytest.mark.parametrize("backend", ["interp", "cpu"])
def test_bit_count_every_width(backend):
    @wp.kernel
    def k(a: wp.array(dtype=wp.int8), b: wp.array(dtype=wp.uint16), c: wp.array(dtype=wp.int64),
          out: wp.array(dtype=wp.int32)):  # fmt: skip
        out[0] = wp.bit_count(a[0])
        out[1] = wp.bit_count(b[0])
        out[2] = wp.bit_count(c[0])
        out[3] = wp.bit_count(45)

    res = _run(k, (np.array([-1], np.int8), wp.int8), (np.array([0x8001], np.uint16), wp.uint16),
               (np.array([-(2**63)], np.int64), wp.int64), (np.zeros(4, np.int32), wp.int32),
               backend=backend)  # fmt: skip
    np.testing.assert_array_equal(res[3], [8, 2, 1, 4])


# --- located errors -------------------------------------------------------------------------


def test_error_trace_of_vector():
    @wp.kernel
    def k(a: F):
        a[0] = wp.trace(wp.vec3())  # <-

    expect_error_at_marker(k, "trace() needs a matrix, not vec<3, f32>")


def test_error_determinant_not_square():
    @wp.kernel
    def k(a: F):
        a[0] = wp.determinant(wp.matrix(shape=(2, 3), dtype=float))  # <-

    expect_error_at_marker(k, "determinant() needs a square matrix")


def test_error_inverse_of_int_matrix():
    @wp.kernel
    def k(a: F):
        m = wp.inverse(wp.identity(n=2, dtype=int))  # <-

    expect_error_at_marker(k, "inverse() needs a float argument")


def test_error_inverse_of_vector():
    @wp.kernel
    def k(a: F):
        m = wp.inverse(wp.vec2())  # <-

    expect_error_at_marker(k, "inverse() needs a square matrix, quaternion or transform")


def test_error_frac_of_int():
    @wp.kernel
    def k(a: F, n: int):
        m = wp.frac(n)  # <-

    expect_error_at_marker(k, "frac() needs a float argument, not i32")


def test_error_lerp_of_ints():
    @wp.kernel
    def k(a: F, n: int):
        m = wp.lerp(n, n, 0.5)  # <-

    expect_error_at_marker(k, "lerp() needs a float argument")


def test_error_cw_mul_mismatch():
    @wp.kernel
    def k(a: F):
        v = wp.cw_mul(wp.vec3(), wp.vec4())  # <-

    expect_error_at_marker(k, "cw_mul() needs two values of one type")


def test_error_identity_size():
    @wp.kernel
    def k(a: F, n: int):
        m = wp.identity(n, float)  # <-

    expect_error_at_marker(k, "n must be a positive integer constant")


def test_error_identity_dtype():
    @wp.kernel
    def k(a: F):
        m = wp.identity(n=3, dtype=wp.vec3)  # <-

    expect_error_at_marker(k, "dtype must be a scalar type")


def test_error_unknown_keyword():
    @wp.kernel
    def k(a: F):
        m = wp.identity(size=3)  # <-

    expect_error_at_marker(k, "takes only n, dtype as keyword arguments (got 'size')")


def test_error_argmin_of_scalar():
    @wp.kernel
    def k(a: F):
        i = wp.argmin(a[0])  # <-

    expect_error_at_marker(k, "argmin() needs a vector, not f32")


def test_error_bit_count_of_float():
    @wp.kernel
    def k(a: F):
        i = wp.bit_count(a[0])  # <-

    expect_error_at_marker(k, "bit_count() needs an integer scalar, not f32")


def test_error_min_of_one_scalar():
    @wp.kernel
    def k(a: F):
        x = wp.min(a[0])  # <-

    expect_error_at_marker(k, "min() of one argument needs a vector")


def test_error_norm_of_int_vector():
    @wp.kernel
    def k(a: F):
        x = wp.norm_huber(wp.vec3i(), 1)  # <-

    expect_error_at_marker(k, "norm_huber() needs a float argument")


def test_error_skew_of_2_vector():
    @wp.kernel
    def k(a: F):
        m = wp.skew(wp.vec2())  # <-

    expect_error_at_marker(k, "skew() needs a 3-vector")


def test_error_matrix_without_shape():
    @wp.kernel
    def k(a: F):
        m = wp.matrix(1.0, 2.0, 3.0, 4.0)  # <-

    expect_error_at_marker(k, "matrix() needs shape=(rows, cols)")


def test_error_svd3_of_2x2():
    @wp.kernel
    def k(a: F):
        U, s, V = wp.svd3(wp.mat22())  # <-

    expect_error_at_marker(k, "no overload of svd3() takes (mat<2, 2, f32>)")


# --- gradients flow through the composed builtins and the library code -----------------------


@wp.kernel
def _grad_kernel(a: wp.array(dtype=wp.mat33d), x: wp.array(dtype=wp.float64),
                 out: wp.array(dtype=wp.float64)):  # fmt: skip
    i = wp.tid()
    m = a[i]
    U, s, V = wp.svd3(m)
    out[i] = (wp.determinant(wp.inverse(m)) + wp.erfinv(x[i]) + wp.lerp(x[i], 2.0 * x[i], 0.3)
              + s[0] + wp.smoothstep(0.0, 1.0, x[i]) + wp.norm_huber(U @ wp.vec3d(x[i]), 0.5))  # fmt: skip


def test_gradients_match_finite_differences():
    if not hasattr(wp, "Tape"):
        pytest.skip("no kdsl.Tape yet")
    rng = np.random.default_rng(0)
    A, X = rng.normal(size=(1, 3, 3)) + 2.0 * np.eye(3), np.array([0.3])

    def value(A, X):
        a, x = wp.from_numpy(A, dtype=wp.mat33d), wp.from_numpy(X, dtype=wp.float64)
        o = wp.zeros(1, dtype=wp.float64)
        wp.launch(_grad_kernel, dim=1, inputs=[a, x, o], backend="cpu")
        return o.numpy()[0]

    a = wp.from_numpy(A, dtype=wp.mat33d, requires_grad=True)
    x = wp.from_numpy(X, dtype=wp.float64, requires_grad=True)
    o = wp.zeros(1, dtype=wp.float64, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(_grad_kernel, dim=1, inputs=[a, x, o], backend="cpu")
    tape.backward(loss=o)
    eps = 1e-6
    fd = np.zeros((3, 3))
    for i in range(3):
        for j in range(3):
            d = np.zeros_like(A)
            d[0, i, j] = eps
            fd[i, j] = (value(A + d, X) - value(A - d, X)) / (2 * eps)
    np.testing.assert_allclose(a.grad.numpy()[0], fd, atol=1e-7)
    fdx = (value(A, X + eps) - value(A, X - eps)) / (2 * eps)
    np.testing.assert_allclose(x.grad.numpy()[0], fdx, rtol=1e-7)
