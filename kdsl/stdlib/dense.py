"""kdsl standard library: Warp's dense linear-algebra helpers (``dense_*``), in kdsl.

Warp 1.19 exports these (hidden from its docs, marked WIP) as kernel builtins over flat
``float32`` arrays holding row-major matrices; each runs serially in the calling
thread, so a kernel typically calls one per thread on its own slice of data (the
batched forms index those slices). Semantics follow Warp's: ``dense_gemm`` writes
``C = op(A) op(B)`` with ``op`` a transpose when ``t1``/``t2`` is 1 (``A`` m x p,
``B`` p x n, ``C`` m x n); ``dense_chol`` writes the lower Cholesky factor of
``A + regularization I`` into ``L`` (n x n; the strict upper triangle is not written);
``dense_subs`` solves ``L L^T x = b`` by forward then backward substitution;
``dense_solve`` is ``dense_subs`` with ``A`` passed along (Warp's adjoint reads it).
The batched forms take per-matrix sizes and start offsets (one entry per matrix) and
process every matrix of the batch in order: Warp 1.19 declares them without a native
implementation, so kdsl gives them this meaning.
"""

import kdsl as wp
from kdsl.frontend.kernel import func

__kdsl_group__ = "linear algebra"

F1 = wp.array[wp.float32]
I1 = wp.array[wp.int32]


@func
def _gemm_at(m: int, n: int, p: int, t1: int, t2: int, A: F1, a0: int, B: F1, b0: int, C: F1,
             c0: int):  # fmt: skip
    for i in range(m):
        for j in range(n):
            s = 0.0
            for k in range(p):
                ia = i * p + k
                if t1 != 0:
                    ia = k * m + i
                ib = k * n + j
                if t2 != 0:
                    ib = j * p + k
                s += A[a0 + ia] * B[b0 + ib]
            C[c0 + i * n + j] = s


@func
def dense_gemm(m: int, n: int, p: int, t1: int, t2: int, A: F1, B: F1, C: F1):
    """``C = op(A) op(B)``, row-major, ``op`` a transpose where ``t1``/``t2`` is 1."""
    _gemm_at(m, n, p, t1, t2, A, 0, B, 0, C, 0)


@func
def dense_gemm_batched(m: I1, n: I1, p: I1, t1: int, t2: int, A_start: I1, B_start: I1,
                       C_start: I1, A: F1, B: F1, C: F1):  # fmt: skip
    """``dense_gemm`` of every matrix ``b`` of the batch (sizes ``m[b], n[b], p[b]``, offsets
    ``*_start[b]``), in order."""
    for b in range(A_start.shape[0]):
        _gemm_at(m[b], n[b], p[b], t1, t2, A, A_start[b], B, B_start[b], C, C_start[b])


@func
def _chol_at(n: int, A: F1, a0: int, regularization: float, L: F1):
    for j in range(n):
        s = A[a0 + j * n + j] + regularization
        for k in range(j):
            r = L[a0 + j * n + k]
            s -= r * r
        s = wp.sqrt(s)
        inv = 1.0 / s
        L[a0 + j * n + j] = s
        for i in range(j + 1, n):
            t = A[a0 + i * n + j]
            for k in range(j):
                t -= L[a0 + i * n + k] * L[a0 + j * n + k]
            L[a0 + i * n + j] = t * inv


@func
def dense_chol(n: int, A: F1, regularization: float, L: F1):
    """The lower Cholesky factor of ``A + regularization I`` (n x n) into ``L``."""
    _chol_at(n, A, 0, regularization, L)


@func
def dense_chol_batched(A_start: I1, A_dim: I1, A: F1, regularization: float, L: F1):
    """``dense_chol`` of every matrix ``b`` (size ``A_dim[b]`` at ``A_start[b]``, same in L)."""
    for b in range(A_start.shape[0]):
        _chol_at(A_dim[b], A, A_start[b], regularization, L)


@func
def _subs_at(n: int, L: F1, l0: int, b: F1, x: F1, x0: int):
    for i in range(n):
        s = b[x0 + i]
        for j in range(i):
            s -= L[l0 + i * n + j] * x[x0 + j]
        x[x0 + i] = s / L[l0 + i * n + i]
    for ii in range(n):
        i = n - 1 - ii
        s = x[x0 + i]
        for j in range(i + 1, n):
            s -= L[l0 + j * n + i] * x[x0 + j]
        x[x0 + i] = s / L[l0 + i * n + i]


@func
def dense_subs(n: int, L: F1, b: F1, x: F1):
    """Solve ``L L^T x = b`` given the Cholesky factor ``L`` (forward, then backward)."""
    _subs_at(n, L, 0, b, x, 0)


@func
def dense_solve(n: int, A: F1, L: F1, b: F1, x: F1):
    """Solve ``A x = b`` given ``L``, the Cholesky factor of ``A`` (``dense_subs``)."""
    _subs_at(n, L, 0, b, x, 0)


@func
def dense_solve_batched(b_start: I1, A_start: I1, A_dim: I1, A: F1, L: F1, b: F1, x: F1):
    """``dense_solve`` of every system ``t``: matrix at ``A_start[t]``, vectors at
    ``b_start[t]``."""
    for t in range(A_start.shape[0]):
        _subs_at(A_dim[t], L, A_start[t], b, x, b_start[t])


__all__ = ["dense_chol", "dense_chol_batched", "dense_gemm", "dense_gemm_batched",
           "dense_solve", "dense_solve_batched", "dense_subs"]  # fmt: skip
