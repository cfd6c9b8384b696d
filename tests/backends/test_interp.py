"""The interp backend: control flow, atomics, calls, thread indices, errors."""

import numpy as np
import pytest

from kdsl.backends import get_backend
from kdsl.backends.interp import InterpBackend
from kdsl.compiler import compile_kernel, lower
from kdsl.errors import KdslError, KdslLaunchError, KdslRuntimeError
from kdsl.ir import parse_module


def run(src: str, dims, *args, kernel: str = "k"):
    backend = get_backend("interp")
    compiled = compile_kernel(backend, parse_module(src), kernel)
    backend.launch(compiled, tuple(dims), list(args))
    return compiled


def kernel(params: str, body: str, extra: str = "") -> str:
    return (
        f'{extra}func.func @k({params}) -> () {{kind = "kernel"}} {{\n{body}\n  func.return\n}}\n'
    )


def test_backend_identity():
    b = get_backend("interp")
    assert isinstance(b, InterpBackend)
    assert b.name == "interp" and b.devices() == ["cpu"] and "fp64" in b.capabilities
    assert b.stages() == ["kir", "kir-opt"]


def test_lower_stages_print_ir():
    src = kernel("%a: array<f32, 1>", "  %i = kd.tid {dim = 0, ndim = 1} : i32")
    b = get_backend("interp")
    assert "kd.tid" in lower(b, parse_module(src), "kir")
    assert "func.func @k" in lower(b, parse_module(src), "kir-opt")
    with pytest.raises(KdslError, match="no stage 'ptx'"):
        lower(b, parse_module(src), "ptx")


def test_scf_if_picks_region_per_thread():
    body = """  %i = kd.tid {dim = 0, ndim = 1} : i32
  %two = arith.constant {value = 2} : i32
  %r = arith.mod %i, %two : i32
  %z = arith.constant {value = 0} : i32
  %c = arith.cmp %r, %z {pred = "eq"} : bool
  %v = scf.if %c : f32 {
    %a = arith.constant {value = 1.5} : f32
    scf.yield %a
  } {
    %b = arith.constant {value = -3.0} : f32
    scf.yield %b
  }
  kd.store %v, %out, %i"""
    out = np.zeros(5, np.float32)
    run(kernel("%out: array<f32, 1>", body), (5,), out)
    np.testing.assert_array_equal(out, [1.5, -3, 1.5, -3, 1.5])


@pytest.mark.parametrize(
    ("lb", "ub", "step", "want"),
    [(0, 5, 1, 10), (5, 0, -2, 5 + 3 + 1), (0, 5, 0, 0), (3, 3, 1, 0), (0, 5, 2, 0 + 2 + 4)],
)
def test_scf_for_sums_induction_variable(lb, ub, step, want):
    body = f"""  %lb = arith.constant {{value = {lb}}} : i32
  %ub = arith.constant {{value = {ub}}} : i32
  %st = arith.constant {{value = {step}}} : i32
  %z = arith.constant {{value = 0}} : i32
  %s = scf.for %lb, %ub, %st, %z : i32 {{
  ^bb(%k: i32, %acc: i32):
    %n = arith.add %acc, %k : i32
    scf.yield %n
  }}
  kd.store %s, %out, %z"""
    out = np.full(1, -1, np.int32)
    run(kernel("%out: array<i32, 1>", body), (1,), out)
    assert out[0] == want


def test_scf_while_counts_to_limit():
    body = """  %i = kd.tid {dim = 0, ndim = 1} : i32
  %one = arith.constant {value = 1} : i32
  %r = scf.while %one : i32 {
  ^bb(%x: i32):
    %c = arith.cmp %x, %n {pred = "lt"} : bool
    scf.condition %c, %x
  } {
  ^bb(%y: i32):
    %z = arith.mul %y, %two : i32
    scf.yield %z
  }
  kd.store %r, %out, %i"""
    out = np.zeros(2, np.int32)
    run(
        kernel("%out: array<i32, 1>, %n: i32, %two: i32", body),
        (2,),
        out,
        np.int32(100),
        np.int32(2),
    )
    np.testing.assert_array_equal(out, [128, 128])


def test_atomic_add_accumulates_and_returns_old_values():
    body = """  %i = kd.tid {dim = 0, ndim = 1} : i32
  %z = arith.constant {value = 0} : i32
  %v = kd.load %x, %i : f32
  %old = kd.atomic_rmw %v, %sum, %z {kind = "add"} : f32
  kd.store %old, %olds, %i
  %m = kd.atomic_rmw %v, %mx, %z {kind = "max"} : f32"""
    x = np.arange(1, 6, dtype=np.float32)
    total, olds, mx = np.zeros(1, np.float32), np.zeros(5, np.float32), np.full(1, -9, np.float32)
    params = "%x: array<f32, 1>, %sum: array<f32, 1>, %olds: array<f32, 1>, %mx: array<f32, 1>"
    run(kernel(params, body), (5,), x, total, olds, mx)
    assert total[0] == 15 and mx[0] == 5
    np.testing.assert_array_equal(olds, [0, 1, 3, 6, 10])


def test_vector_arrays_load_and_store_whole_elements():
    body = """  %i = kd.tid {dim = 0, ndim = 1} : i32
  %v = kd.load %a, %i : vec<3, f32>
  %w = arith.mul %v, %s : vec<3, f32>
  kd.store %w, %a, %i"""
    a = np.arange(6, dtype=np.float32).reshape(2, 3)
    run(kernel("%a: array<vec<3, f32>, 1>, %s: f32", body), (2,), a, np.float32(2))
    np.testing.assert_array_equal(a, np.arange(6).reshape(2, 3) * 2)


def test_func_call_through_ctx_call():
    callee = """func.func @sq(%x: f32) -> (f32) {kind = "func"} {
  %y = arith.mul %x, %x : f32
  func.return %y
}
"""
    body = """  %i = kd.tid {dim = 0, ndim = 1} : i32
  %v = kd.load %a, %i : f32
  %w = func.call %v {callee = "sq"} : f32
  kd.store %w, %a, %i"""
    a = np.array([1, 2, 3], np.float32)
    run(kernel("%a: array<f32, 1>", body, extra=callee), (3,), a)
    np.testing.assert_array_equal(a, [1, 4, 9])


@pytest.mark.parametrize("dims", [(3,), (2, 3), (2, 3, 2), (2, 1, 3, 2)])
def test_tid_in_every_rank_is_row_major(dims):
    nd = len(dims)
    comps = "\n".join(f"  %t{d} = kd.tid {{dim = {d}, ndim = {nd}}} : i32" for d in range(nd))
    idx = ", ".join(f"%t{d}" for d in range(nd))
    body = f"""{comps}
  %lin = kd.tid {{dim = 0, ndim = 1}} : i32
  kd.store %lin, %out, {idx}"""
    out = np.full(dims, -1, np.int32)
    run(kernel(f"%out: array<i32, {nd}>", body), dims, out)
    np.testing.assert_array_equal(out, np.arange(np.prod(dims)).reshape(dims))


def test_tid_rank_must_match_launch():
    body = """  %i = kd.tid {dim = 0, ndim = 2} : i32
  %j = kd.tid {dim = 1, ndim = 2} : i32
  kd.store %j, %out, %i"""
    with pytest.raises(KdslLaunchError, match="2-d thread index"):
        run(kernel("%out: array<i32, 1>", body), (4,), np.zeros(4, np.int32))


def test_out_of_bounds_raises_with_details_and_process_stays_usable():
    body = """  %i = kd.tid {dim = 0, ndim = 1} : i32
  %v = kd.load %a, %i : f32
  kd.store %v, %b, %i"""
    src = kernel("%a: array<f32, 1>, %b: array<f32, 1>", body)
    a, b = np.arange(4, dtype=np.float32), np.zeros(3, np.float32)
    with pytest.raises(KdslRuntimeError) as info:
        run(src, (4,), a, b)
    msg = str(info.value)
    assert "index [3] is out of bounds for array 'b' of shape (3,)" in msg
    assert "kernel 'k'" in msg and "thread 3" in msg
    np.testing.assert_array_equal(b, [0, 1, 2])  # threads before the bad one ran
    b2 = np.zeros(4, np.float32)
    run(src, (4,), a, b2)
    np.testing.assert_array_equal(b2, a)


def test_compiled_kernel_reports_tid_ranks():
    src = kernel(
        "%out: array<i32, 1>", "  %i = kd.tid {dim = 0, ndim = 1} : i32\n  kd.store %i, %out, %i"
    )
    assert run(src, (0,), np.zeros(0, np.int32)).metadata["tid_ndims"] == [1]
