"""quat_between_vectors, transform_expand and the dense_* helpers against NumPy."""

import numpy as np
import pytest

import kdsl as wp

BACKENDS = ["interp", "cpu"]


@wp.kernel
def _between(a: wp.array(dtype=wp.vec3), b: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    q = wp.quat_between_vectors(a[i], b[i])
    out[i] = wp.quat_rotate(q, wp.normalize(a[i]))


@pytest.mark.parametrize("backend", BACKENDS)
def test_quat_between_vectors_rotates_a_onto_b(backend):
    rng = np.random.default_rng(1)
    a = rng.standard_normal((64, 3)).astype(np.float32)
    b = rng.standard_normal((64, 3)).astype(np.float32) * 3.0
    out = wp.zeros(64, dtype=wp.vec3)
    wp.launch(_between, 64, [wp.array(a, dtype=wp.vec3), wp.array(b, dtype=wp.vec3), out],
              backend=backend)  # fmt: skip
    want = b / np.linalg.norm(b, axis=1, keepdims=True)
    np.testing.assert_allclose(out.numpy(), want, atol=2e-5)


def test_quat_between_vectors_python_scope_and_float64():
    q = wp.quat_between_vectors(wp.vec3(1.0, 0.0, 0.0), wp.vec3(0.0, 2.0, 0.0))
    s = np.sqrt(0.5)
    np.testing.assert_allclose(np.array(q), [0.0, 0.0, s, s], atol=1e-6)
    qd = wp.quat_between_vectors(wp.vec3d(0.0, 0.0, 1.0), wp.vec3d(0.0, 0.0, 5.0))
    np.testing.assert_allclose(np.array(qd), [0.0, 0.0, 0.0, 1.0])


def test_transform_expand():
    t = wp.transform_expand([1, 2, 3, 0.0, 0.0, 0.0, 1.0])
    assert isinstance(t, wp.transformf)
    np.testing.assert_allclose(np.array(t.p), [1, 2, 3])
    np.testing.assert_allclose(np.array(t.q), [0, 0, 0, 1])
    np.testing.assert_allclose(np.array(wp.transform_expand(np.arange(7.0))), np.arange(7.0))
    with pytest.raises(wp.KdslTypeError, match="7 numbers"):
        wp.transform_expand([1, 2, 3])
    with pytest.raises(wp.KdslTypeError, match="7 numbers"):
        wp.transform_expand("abc")


@wp.kernel
def _dense(A: wp.array(dtype=float), B: wp.array(dtype=float), C: wp.array(dtype=float),
           S: wp.array(dtype=float), L: wp.array(dtype=float), b: wp.array(dtype=float),
           x: wp.array(dtype=float), t1: int, t2: int):  # fmt: skip
    wp.dense_gemm(2, 3, 4, t1, t2, A, B, C)
    wp.dense_chol(3, S, 0.5, L)
    wp.dense_solve(3, S, L, b, x)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("t1, t2", [(0, 0), (1, 1)])
def test_dense_gemm_chol_solve(backend, t1, t2):
    rng = np.random.default_rng(2)
    A = rng.standard_normal(8).astype(np.float32)
    B = rng.standard_normal(12).astype(np.float32)
    M = rng.standard_normal((3, 3))
    S = (M @ M.T + np.eye(3)).astype(np.float32)
    rhs = rng.standard_normal(3).astype(np.float32)
    C, L, x = (wp.zeros(n, dtype=float) for n in (6, 9, 3))
    wp.launch(_dense, 1, [wp.array(A), wp.array(B), C, wp.array(S.ravel()), L, wp.array(rhs), x,
                          t1, t2], backend=backend)  # fmt: skip
    opA = A.reshape(4, 2).T if t1 else A.reshape(2, 4)
    opB = B.reshape(3, 4).T if t2 else B.reshape(4, 3)
    np.testing.assert_allclose(C.numpy().reshape(2, 3), opA @ opB, rtol=1e-5, atol=1e-5)
    Sr = S.astype(np.float64) + 0.5 * np.eye(3)
    np.testing.assert_allclose(np.tril(L.numpy().reshape(3, 3)), np.linalg.cholesky(Sr),
                               rtol=1e-5, atol=1e-5)  # fmt: skip
    np.testing.assert_allclose(x.numpy(), np.linalg.solve(Sr, rhs), rtol=1e-4, atol=1e-5)


@wp.kernel
def _dense_batched(m: wp.array(dtype=int), n: wp.array(dtype=int), p: wp.array(dtype=int),
                   starts: wp.array(dtype=int), c_starts: wp.array(dtype=int),
                   A: wp.array(dtype=float), B: wp.array(dtype=float), C: wp.array(dtype=float),
                   dims: wp.array(dtype=int), S: wp.array(dtype=float), L: wp.array(dtype=float),
                   vstarts: wp.array(dtype=int), b: wp.array(dtype=float),
                   x: wp.array(dtype=float)):  # fmt: skip
    wp.dense_gemm_batched(m, n, p, 0, 0, starts, starts, c_starts, A, B, C)
    wp.dense_chol_batched(starts, dims, S, 0.0, L)
    wp.dense_solve_batched(vstarts, starts, dims, S, L, b, x)


@pytest.mark.parametrize("backend", BACKENDS)
def test_dense_batched_every_matrix_of_the_batch(backend):
    rng = np.random.default_rng(3)
    mats = [rng.standard_normal((2, 2)) for _ in range(2)]
    spd = [(mm @ mm.T + np.eye(2)) for mm in mats]
    rhs = rng.standard_normal(4)
    ints = lambda v: wp.array(np.array(v, np.int32), dtype=int)  # noqa: E731
    flat = lambda ms: wp.array(np.concatenate([q.ravel() for q in ms]).astype(np.float32))  # noqa: E731
    C, L, x = wp.zeros(8, dtype=float), wp.zeros(8, dtype=float), wp.zeros(4, dtype=float)
    wp.launch(_dense_batched, 1, [ints([2, 2]), ints([2, 2]), ints([2, 2]), ints([0, 4]),
                                  ints([0, 4]), flat(mats), flat(mats), C, ints([2, 2]),
                                  flat(spd), L, ints([0, 2]), wp.array(rhs.astype(np.float32)),
                                  x], backend=backend)  # fmt: skip
    for k in range(2):
        np.testing.assert_allclose(C.numpy()[4 * k : 4 * k + 4].reshape(2, 2),
                                   mats[k] @ mats[k], rtol=1e-5, atol=1e-5)  # fmt: skip
        np.testing.assert_allclose(x.numpy()[2 * k : 2 * k + 2],
                                   np.linalg.solve(spd[k], rhs[2 * k : 2 * k + 2]), rtol=1e-4,
                                   atol=1e-5)  # fmt: skip
