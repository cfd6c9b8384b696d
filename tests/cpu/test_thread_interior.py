"""Boundary peeling of the thread loop (``kdsl.passes.thread_interior`` + cpu lowering).

Kernels with bounds tests on their thread index run on the cpu backend (edge loops
plus a folded interior loop) and on the interpreter; the results must be the same
bit for bit on shapes that hit every edge, single rows and columns, empty
interiors and launches the thread pool splits in the middle of a row.
"""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.backends.cpu import BACKEND as CPU
from kdsl.backends.cpu import set_num_threads
from kdsl.backends.interp import BACKEND as INTERP
from kdsl.compiler import compile_kernel, lower


@wp.kernel
def jacobi(u: wp.array2d(dtype=float), out: wp.array2d(dtype=float)):
    # The edge test of the benchmarks' Jacobi, spelled with every predicate.
    i, j = wp.tid()
    edge = i < 1 or j <= 0 or i + 1 >= u.shape[0]
    if edge or u.shape[1] - 1 == j:
        out[i, j] = u[i, j]
    else:
        out[i, j] = 0.25 * (u[i - 1, j] + u[i + 1, j] + u[i, j - 1] + u[i, j + 1])


@wp.kernel
def one_sided(u: wp.array2d(dtype=float), out: wp.array2d(dtype=float), n: int):
    # Offsets on the index, a parameter bound, operands swapped, a ``!=`` test.
    i, j = wp.tid()
    v = -1.0
    if j + 1 < n and 1 <= i and j - 2 >= 0:  # noqa: SIM300 (operands swapped on purpose)
        v = u[i - 1, j] + u[i, j - 2]
    if j != u.shape[1] - 2:
        v = v * 2.0
    if i > 2:
        v = v + 0.5
    out[i, j] = v


@wp.kernel
def flat(x: wp.array(dtype=float), out: wp.array(dtype=float), n: int):
    i = wp.tid()
    if i < n:
        out[i] = x[i] * 3.0
    elif i >= n + 2:
        out[i] = x[i] - 1.0
    else:
        out[i] = 7.0


@wp.kernel
def box3(u: wp.array3d(dtype=float), out: wp.array3d(dtype=float)):
    i, j, k = wp.tid()
    if i == 0 or k == u.shape[2] - 1:
        out[i, j, k] = -u[i, j, k]
    else:
        out[i, j, k] = u[i - 1, j, k] + u[i, j, k + 1]


@wp.kernel
def no_tests(u: wp.array2d(dtype=float), out: wp.array2d(dtype=float)):
    i, j = wp.tid()
    out[i, j] = u[i, j] + 1.0


def _run(kernel, dims: tuple, inputs: list, outs: int = 1) -> list[np.ndarray]:
    """The outputs (the last ``outs`` inputs) on cpu and on the interpreter."""
    got = []
    for backend in (CPU, INTERP):
        args = [a.copy() if isinstance(a, np.ndarray) else a for a in inputs]
        backend.launch(compile_kernel(backend, kernel), dims, args)
        got.append([a for a in args if isinstance(a, np.ndarray)][-outs:])
    return got


def _same(got: list) -> None:
    for a, b in zip(*got):
        assert np.array_equal(a, b, equal_nan=True)


def _field(shape: tuple, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).random(shape).astype(np.float32)


SHAPES_2D = [(1, 1), (1, 6), (6, 1), (2, 2), (3, 3), (2, 9), (5, 7), (40, 67)]


@pytest.mark.parametrize("shape", SHAPES_2D)
def test_jacobi_matches_interp(shape):
    u = _field(shape)
    _same(_run(jacobi, shape, [u, np.zeros_like(u)]))


@pytest.mark.parametrize("shape", [(4, 9), (7, 3), (1, 5)])
@pytest.mark.parametrize("n", [-4, 0, 3, 8, 9, 30])
def test_offsets_and_parameter_bounds(shape, n):
    u = _field(shape, 1)
    _same(_run(one_sided, shape, [u, np.zeros_like(u), n]))


@pytest.mark.parametrize("n", [-5, 0, 1, 20, 36, 37, 40])
def test_flat_launch(n):
    x = _field((37,), 2)
    _same(_run(flat, (37,), [x, np.zeros_like(x), n]))


@pytest.mark.parametrize("shape", [(1, 1, 1), (3, 2, 4), (4, 5, 1), (6, 3, 17)])
def test_three_dimensions(shape):
    u = _field(shape, 3)
    _same(_run(box3, shape, [u, np.zeros_like(u)]))


def test_pool_splits_rows():
    """Ranges that start and end inside rows (two workers, an odd row length)."""
    set_num_threads(2)
    try:
        u = _field((301, 257), 4)
        _same(_run(jacobi, u.shape, [u, np.zeros_like(u)]))
        out = np.zeros_like(u)
        CPU.launch(compile_kernel(CPU, one_sided), u.shape, [u, out, 200])
        want = np.zeros_like(u)
        INTERP.launch(compile_kernel(INTERP, one_sided), u.shape, [u, want, 200])
        assert np.array_equal(out, want)
    finally:
        set_num_threads(None)


def test_peeled_loops_in_the_llvm_ir():
    """A kernel with bounds tests gets an interior column loop; one without does not."""
    assert "col.inner.body" in lower(CPU, jacobi, "llvm-ir")
    assert "thread.inner.body" in lower(CPU, flat, "llvm-ir")
    assert "inner" not in lower(CPU, no_tests, "llvm-ir")


def test_debug_builds_match():
    """Checked builds (one loop: a failed check ends its thread there) agree too."""
    u = _field((9, 11), 5)
    got = []
    for backend in (CPU, INTERP):
        out = np.zeros_like(u)
        compiled = compile_kernel(backend, jacobi, None, {"debug": True})
        backend.launch(compiled, u.shape, [u.copy(), out])
        got.append([out])
    _same(got)
