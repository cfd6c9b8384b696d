"""Scalarized vectors on cpu: calls, dynamic indices, versioned loops, bit-exact vs interp."""

from __future__ import annotations

import re

import numpy as np
import pytest

from kdsl.backends.cpu import BACKEND as CPU
from kdsl.backends.cpu.lower import lower_kernels
from kdsl.backends.interp import BACKEND as INTERP
from kdsl.compiler import compile_kernel, lower
from kdsl.ir.parser import parse_module

# A function taking and giving vectors, a matrix and a struct holding a vector, called
# without inlining: the values cross the call as their scalar parts.
CALL = """struct S {v: vec<3, f32>, k: i32}
func.func @f(%v: vec<3, f32>, %m: mat<3, 3, f32>, %s: struct<S>) -> (vec<3, f32>, struct<S>) {kind = "func", res_types = [type(vec<3, f32>), type(struct<S>)]} {
  %w = vec.matmul %m, %v : vec<3, f32>
  %sv = struct.extract %s {field = "v"} : vec<3, f32>
  %x = vec.cross %w, %sv : vec<3, f32>
  %t = struct.insert %s, %x {field = "v"} : struct<S>
  func.return %w, %t
}
func.func @k(%a: array<vec<3, f32>, 1>, %m: mat<3, 3, f32>, %s: struct<S>, %o: array<vec<3, f32>, 1>) -> () {kind = "kernel"} {
  %i = kd.tid {dim = 0, ndim = 1} : i32
  %v = kd.load %a, %i : vec<3, f32>
  %w, %t = func.call %v, %m, %s {callee = "f"} : vec<3, f32>, struct<S>
  %tv = struct.extract %t {field = "v"} : vec<3, f32>
  %r = arith.add %w, %tv : vec<3, f32>
  kd.store %r, %o, %i
  func.return
}"""

# Dynamic component and row indices (select chains) on a vector and a matrix.
DYNAMIC = """func.func @k(%a: array<vec<3, f32>, 1>, %m: array<mat<3, 3, f32>, 1>, %j: array<i32, 1>, %o: array<vec<3, f32>, 1>) -> () {kind = "kernel"} {
  %i = kd.tid {dim = 0, ndim = 1} : i32
  %v = kd.load %a, %i : vec<3, f32>
  %mm = kd.load %m, %i : mat<3, 3, f32>
  %k = kd.load %j, %i : i32
  %x = vec.extract %v, %k : f32
  %row = vec.extract %mm, %k : vec<3, f32>
  %e = vec.extract %mm, %k, %k : f32
  %y = arith.mul %row, %x : vec<3, f32>
  %z = vec.insert %y, %e, %k : vec<3, f32>
  %m2 = vec.insert %mm, %z, %k : mat<3, 3, f32>
  %t = vec.transpose %m2 : mat<3, 3, f32>
  %r = vec.matmul %t, %z : vec<3, f32>
  kd.store %r, %o, %i
  func.return
}"""

# An innermost loop over a vec3 array: versioned on the array being dense.
LOOP = """func.func @k(%a: array<vec<3, f32>, 1>, %o: array<vec<3, f32>, 1>) -> () {kind = "kernel"} {
  %i = kd.tid {dim = 0, ndim = 1} : i32
  %p = kd.load %a, %i : vec<3, f32>
  %zero = arith.constant {value = 0} : i32
  %one = arith.constant {value = 1} : i32
  %n = kd.array_shape %a {dim = 0} : i32
  %acc = scf.for %zero, %n, %one, %p : vec<3, f32> {
  ^bb(%j: i32, %s: vec<3, f32>):
    %q = kd.load %a, %j : vec<3, f32>
    %d = arith.sub %q, %p : vec<3, f32>
    %l = vec.length %d : f32
    %u = arith.mul %d, %l : vec<3, f32>
    %s2 = arith.add %s, %u : vec<3, f32>
    scf.yield %s2
  }
  kd.store %acc, %o, %i
  func.return
}"""


def _run(text: str, args_for, n: int) -> list[np.ndarray]:
    outs = []
    for backend in (CPU, INTERP):
        args = args_for()
        compiled = compile_kernel(backend, parse_module(text), "k", {"optimize": False})
        backend.launch(compiled, (n,), args)
        outs.append(args[-1])
    return outs


def _same(a: np.ndarray, b: np.ndarray) -> None:
    assert a.tobytes() == b.tobytes(), np.max(np.abs(a - b))


def _close(a: np.ndarray, b: np.ndarray) -> None:
    # interp's matmul is NumPy's (its own summation order), so a last-bit difference is ok
    np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6)


def test_call_with_vector_matrix_struct_parts() -> None:
    rng = np.random.default_rng(0)
    a = rng.normal(size=(6, 3)).astype(np.float32)
    m = rng.normal(size=(3, 3)).astype(np.float32)
    s = (np.array([0.5, -1.0, 2.0], np.float32), np.int32(3))
    got, want = _run(CALL, lambda: [a, m, s, np.zeros((6, 3), np.float32)], 6)
    _close(got, want)
    text = str(lower_kernels(parse_module(CALL), ["k"]).llmod)
    (define,) = [ln for ln in text.splitlines() if ln.startswith("define internal")]
    # returns vec3 + struct{vec3, i32} as 7 leaves; takes vec3, mat33, struct as 16
    assert define.startswith("define internal {" + "float, " * 6 + "i32}")
    assert define.count("float %") == 3 + 9 + 3 and define.count("i32 %") == 1
    assert "<3 x float>" not in text


def test_dynamic_indices() -> None:
    rng = np.random.default_rng(1)
    a = rng.normal(size=(9, 3)).astype(np.float32)
    m = rng.normal(size=(9, 3, 3)).astype(np.float32)
    j = (np.arange(9) % 3).astype(np.int32)
    got, want = _run(DYNAMIC, lambda: [a, m, j, np.zeros((9, 3), np.float32)], 9)
    _close(got, want)


@pytest.mark.parametrize("step", [1, 2])
def test_versioned_loop_dense_and_strided(step: int) -> None:
    rng = np.random.default_rng(2)
    base = rng.normal(size=(14, 3)).astype(np.float32)
    a = base[::step]  # step 2: a strided view, the general copy of the loop runs
    got, want = _run(LOOP, lambda: [a, np.zeros((len(a), 3), np.float32)], len(a))
    _same(got, want)


def test_loop_is_versioned_and_scalar() -> None:
    text = lower(CPU, parse_module(LOOP), "llvm-ir-unopt")
    assert "dense.loop" in text and "strided.loop" in text
    assert "<3 x float>" not in text


# A thread loop over arrays of vectors with no loop of its own: the seeds' integrate.
THREADS = """func.func @k(%x: array<vec<3, f32>, 1>, %v: array<vec<3, f32>, 1>, %dt: f32, %o: array<vec<3, f32>, 1>) -> () {kind = "kernel"} {
  %i = kd.tid {dim = 0, ndim = 1} : i32
  %p = kd.load %x, %i : vec<3, f32>
  %w = kd.load %v, %i : vec<3, f32>
  %s = arith.mul %w, %dt : vec<3, f32>
  %q = arith.add %p, %s : vec<3, f32>
  kd.store %q, %o, %i
  func.return
}"""


@pytest.mark.parametrize("step", [1, 2])
def test_versioned_thread_loop_dense_and_strided(step: int) -> None:
    rng = np.random.default_rng(3)
    x = rng.normal(size=(40, 3)).astype(np.float32)[::step]
    v = rng.normal(size=(40, 3)).astype(np.float32)[::step]
    n = len(x)
    got, want = _run(THREADS, lambda: [x, v, np.float32(0.25), np.zeros((n, 3), np.float32)], n)
    _same(got, want)


def test_thread_loop_over_vector_arrays_vectorizes() -> None:
    text = lower(CPU, parse_module(THREADS), "llvm-ir")
    assert "dense.loop" in text or "vector.body" in text
    # The dense copy of the thread loop works on several threads' components at once. The
    # width is the host's choice (8 or 16 with AVX2, 24 or 48 with AVX-512): wider than a
    # single vec3 is what matters.
    widths = [int(w) for w in re.findall(r"fmul <(\d+) x float>", text)]
    assert max(widths, default=0) >= 4, "the thread loop was not vectorized"
