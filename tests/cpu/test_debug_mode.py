"""Debug mode: bounds checks and NaN/Inf checks on the cpu backend (and on interp)."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl import config
from kdsl.backends.cpu.lower import lower_kernels
from kdsl.compiler import compile_kernel, lower
from kdsl.errors import KdslRuntimeError
from kdsl.ir import parse_module
from kdsl.passes import run_pipeline

BACKENDS = ["cpu", "interp"]


@pytest.fixture(params=BACKENDS)
def backend(request, cpu_backend):
    return request.param


def f32(values) -> wp.array:
    return wp.array(np.asarray(values, dtype=np.float32))


def launch_error(kernel, dim, inputs, backend) -> KdslRuntimeError:
    with pytest.raises(KdslRuntimeError) as info:
        wp.launch(kernel, dim=dim, inputs=inputs, backend=backend)
    return info.value


@wp.kernel(debug=True)
def read_past(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = x[i + 2] * 2.0


@wp.kernel(debug=True)
def write_past(y: wp.array(dtype=float)):
    i = wp.tid()
    y[i + 1] = 1.0


@wp.kernel(debug=True)
def read_before(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = x[i - 1]


@wp.kernel(debug=True)
def grid(m: wp.array2d(dtype=float)):
    i, j = wp.tid()
    m[i, j + 1] = float(i)


@wp.kernel(debug=True)
def count(hist: wp.array(dtype=float), bins: wp.array(dtype=int)):
    i = wp.tid()
    wp.atomic_add(hist, bins[i], 1.0)


@wp.kernel(debug=True)
def loop_if(x: wp.array(dtype=float), y: wp.array(dtype=float), n: int):
    i = wp.tid()
    s = 0.0
    for k in range(n):
        if k > 1:
            s += x[k + i]
    y[i] = s


@wp.kernel(debug=True)
def two_bad(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = x[i + 3]
    y[i + 3] = x[i]


def test_oob_load_names_array_index_shape_and_line(backend):
    e = launch_error(read_past, 4, [f32(range(4)), f32(np.zeros(4))], backend)
    text = str(e)
    assert "index [4] is out of bounds for array 'x' of shape (4,) in kernel 'read_past'" in text
    assert "test_debug_mode.py" in text and "y[i] = x[i + 2] * 2.0" in text
    assert "^" in text and "in thread 2" in text


def test_oob_store(backend):
    e = launch_error(write_past, 4, [f32(np.zeros(4))], backend)
    assert "index [4] is out of bounds for array 'y' of shape (4,)" in str(e)
    assert "y[i + 1] = 1.0" in str(e)


def test_negative_index(backend):
    e = launch_error(read_before, 3, [f32(range(3)), f32(np.zeros(3))], backend)
    assert "index [-1] is out of bounds for array 'x' of shape (3,)" in str(e)
    assert "in thread 0" in str(e)


def test_2d_array(backend):
    m = wp.array(np.zeros((3, 4), dtype=np.float32))
    e = launch_error(grid, (3, 4), [m], backend)
    assert "index [0, 4] is out of bounds for array 'm' of shape (3, 4)" in str(e)
    assert "in thread (0, 3)" in str(e)


def test_atomic(backend):
    bins = wp.array(np.array([0, 1, 7, 1], dtype=np.int32))
    e = launch_error(count, 4, [f32(np.zeros(3)), bins], backend)
    assert "index [7] is out of bounds for array 'hist' of shape (3,)" in str(e)
    assert "wp.atomic_add(hist, bins[i], 1.0)" in str(e)


def test_in_loop_and_if(backend):
    y = f32(np.zeros(2))
    wp.launch(loop_if, dim=2, inputs=[f32(range(5)), y, 4], backend=backend)
    assert y.numpy().tolist() == [5.0, 7.0]
    e = launch_error(loop_if, 2, [f32(range(5)), y, 5], backend)
    assert "index [5] is out of bounds for array 'x' of shape (5,)" in str(e)
    assert "s += x[k + i]" in str(e)


def test_first_failing_access_is_reported(backend):
    # Thread 0 fails first at x[i + 3]; the failing thread stops there.
    e = launch_error(two_bad, 2, [f32(range(4)), f32(np.zeros(4))], backend)
    assert "index [4] is out of bounds for array 'x'" in str(e)
    assert "in thread 1" in str(e)


def test_failing_thread_touches_no_memory_and_process_stays_usable(backend):
    big = np.zeros(8, dtype=np.float32)
    y = wp.array(big[:4], copy=False)
    launch_error(write_past, 4, [y], backend)
    assert big.tolist() == [0, 1, 1, 1, 0, 0, 0, 0]  # nothing written past the end
    x, out = f32([1, 2, 3, 4, 5, 6]), f32(np.zeros(4))
    wp.launch(read_past, dim=4, inputs=[x, out], backend=backend)
    assert out.numpy().tolist() == [6.0, 8.0, 10.0, 12.0]


def test_large_parallel_launch_reports_a_failure(cpu_backend):
    n = 100_000
    e = launch_error(write_past, n, [f32(np.zeros(n))], "cpu")
    assert f"index [{n}] is out of bounds for array 'y' of shape ({n},)" in str(e)


@wp.kernel
def plain_read_past(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = x[i + 2]


def test_config_mode_turns_checks_on_and_kernel_option_wins(monkeypatch, cpu_backend):
    x, y = f32(range(4)), f32(np.zeros(4))
    monkeypatch.setattr(config, "mode", "debug")
    e = launch_error(plain_read_past, 4, [x, y], "cpu")
    assert "array 'x'" in str(e)

    @wp.kernel(mode="release")
    def released(x: wp.array(dtype=float), y: wp.array(dtype=float)):
        i = wp.tid()
        y[i] = x[i]

    wp.launch(released, dim=4, inputs=[x, y], backend="cpu")
    assert y.numpy().tolist() == [0, 1, 2, 3]
    assert config.compile_options(released.options).get("debug") is None


def test_compile_options_resolution(monkeypatch):
    assert config.compile_options({"enable_backward": True}) == {"enable_backward": True}
    assert config.compile_options({"debug": True})["debug"] is True
    assert "debug" not in config.compile_options({"mode": "release"})
    monkeypatch.setattr(config, "verify_fp", True)
    assert config.compile_options({})["verify_fp"] is True
    monkeypatch.setattr(config, "mode", "fast")
    with pytest.raises(wp.KdslError, match="'release' or 'debug'"):
        config.compile_options({})


def test_release_llvm_ir_has_no_checks(cpu_backend):
    module = plain_read_past.build_module()
    release = lower(cpu_backend, module, "llvm-ir")
    assert "cmpxchg" not in release and "bounds." not in release
    debug_module = run_pipeline(plain_read_past.build_module(), "inline,dce,bounds-check")
    text = str(lower_kernels(debug_module, [plain_read_past.key], debug=True).llmod)
    assert "cmpxchg" in text and "bounds.fail" in text


def test_debug_and_release_builds_are_cached_apart(cpu_backend):
    @wp.kernel
    def k(x: wp.array(dtype=float)):
        i = wp.tid()
        x[i + 1] = 2.0

    big = np.zeros(8, dtype=np.float32)
    wp.launch(k, dim=2, inputs=[wp.array(big[:4], copy=False)], backend="cpu")
    k.options["debug"] = True
    launch_error(k, 4, [f32(np.zeros(4))], "cpu")
    assert len(k._kdsl_compiled) == 2


@wp.kernel(verify_fp=True)
def make_nan(x: wp.array(dtype=float), y: wp.array(dtype=float), z: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = x[i] / x[i]
    z[i] = 1.0 / x[i]


def test_verify_fp_names_the_first_line(backend):
    y, z = f32(np.zeros(3)), f32(np.zeros(3))
    e = launch_error(make_nan, 3, [f32([0, 1, 2]), y, z], backend)
    text = str(e)
    assert "kernel 'make_nan' produced NaN" in text and "array 'y'" in text
    assert "y[i] = x[i] / x[i]" in text and "in thread 0" in text


def test_verify_fp_inf_and_clean_run(backend):
    y, z = f32(np.zeros(2)), f32(np.zeros(2))
    wp.launch(make_nan, dim=2, inputs=[f32([1, 2]), y, z], backend=backend)
    assert z.numpy().tolist() == [1.0, 0.5]
    e = launch_error(make_nan, 1, [f32([np.inf]), y, z], backend)
    assert "produced NaN" in str(e)
    with pytest.raises(KdslRuntimeError, match=r"produced Inf .*array 'v'") as info:
        v = wp.zeros(3, dtype=wp.vec3)
        wp.launch(make_inf, dim=3, inputs=[f32([3, 0, 0]), v], backend=backend)
    assert "v[i] = vec_of(x[i])" in str(info.value) and "thread 1" in str(info.value)


@wp.func
def vec_of(a: float):
    return wp.vec3(1.0, 1.0 / a, 2.0)


@wp.kernel(verify_fp=True)
def make_inf(x: wp.array(dtype=float), v: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    v[i] = vec_of(x[i])


RECURSIVE = """
func.func @k(%a: array<f32, 1>, %n: i32) -> () {kind = "kernel"} {
  %i = kd.tid {dim = 0, ndim = 1} : i32
  func.call %a, %n {callee = "f"}
  %one = arith.constant {value = 1.0} : f32
  kd.store %one, %a, %i
  func.return
}
func.func @f(%b: array<f32, 1>, %m: i32) -> () {kind = "func"} {
  %z = arith.constant {value = 0} : i32
  %c = arith.cmp %m, %z {pred = "gt"} : bool
  scf.if %c {
    %v = arith.constant {value = 2.0} : f32
    kd.store %v, %b, %m
    %one = arith.constant {value = 1} : i32
    %m1 = arith.sub %m, %one : i32
    func.call %b, %m1 {callee = "f"}
    scf.yield
  } {
    scf.yield
  }
  func.return
}
"""


def test_check_in_called_function_stops_the_caller(cpu_backend):
    # optimize=False keeps the call (the inliner refuses recursion).
    options = {"debug": True, "optimize": False}
    compiled = compile_kernel(cpu_backend, parse_module(RECURSIVE), "k", options)
    buf = np.zeros(4, dtype=np.float32)
    cpu_backend.launch(compiled, (2,), [buf, np.int32(3)])
    assert buf.tolist() == [1, 1, 2, 2]
    buf[:] = 0
    with pytest.raises(KdslRuntimeError) as info:
        cpu_backend.launch(compiled, (2,), [buf, np.int32(4)])
    assert "index [4] is out of bounds for array 'b' of shape (4,)" in str(info.value)
    assert "in function 'f'" in str(info.value)
    assert buf.tolist() == [0, 0, 0, 0]  # the failing threads stopped before their store
