"""The cuda backend without a GPU: CUDA C generation and NVRTC compilation (sm_90).

Every conformance kernel is lowered and compiled (several per NVRTC call: one
call costs ~80 ms of fixed overhead); the rest checks the generated code's shape.
"""

from __future__ import annotations

import re
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("cupy_backends.cuda.libs.nvrtc")

import kdsl as wp
from kdsl.backends.cuda import BACKEND, nvrtc, ops
from kdsl.backends.cuda.lower import generate
from kdsl.backends.cuda.params import Packer
from kdsl.compiler import compile_kernel, lower
from kdsl.errors import KdslError
from kdsl.ir import parse_module
from kdsl.ir import types as T
from kdsl.passes import DEFAULT_PIPELINE, run_pipeline
from kdsl.testing.cases import all_cases

ARCH = "sm_90"
CASES = all_cases()
BATCH = 28


def _optimized(kernel, checks: str = ""):
    m = kernel.build_module()
    run_pipeline(m, DEFAULT_PIPELINE + ("," + checks if checks else ""))
    return m


def _units(cases, checks: str = "") -> list[tuple[str, str]]:
    """(case name, generated unit) per distinct kernel of ``cases``."""
    out, seen = [], set()
    for case in cases:
        gen = generate(_optimized(case.kernel, checks), [case.kernel.key], debug=bool(checks))
        if case.kernel.key not in seen:
            seen.add(case.kernel.key)
            out.append((case.name, gen.text))
    return out


def _compile_batch(units: list[tuple[str, str]]) -> None:
    """Compile units together (each in its own namespace); on failure, name the case."""
    joined = "".join(f"namespace kd_case{i} {{\n{u}}}\n" for i, (_, u) in enumerate(units))
    try:
        nvrtc.compile_source(joined, ARCH)
    except KdslError:
        for name, unit in units:
            try:
                nvrtc.compile_source(unit, ARCH)
            except KdslError as e:
                pytest.fail(f"case {name}: {e}\n{unit}")
        raise


@pytest.mark.parametrize("start", range(0, len(CASES), BATCH))
def test_every_conformance_kernel_compiles(start):
    _compile_batch(_units(CASES[start : start + BATCH]))


DEBUG_CASES = ["program_saxpy", "tid_2d", "func_early_return_in_loop", "vec3_arrays",
               "atomic_add_contention", "float16_arrays", "program_nbody"]  # fmt: skip


def test_debug_builds_compile():
    cases = [c for c in CASES if c.name in DEBUG_CASES]
    assert len(cases) == len(DEBUG_CASES)
    units = _units(cases, "bounds-check,fp-check")
    assert all("kd_err" in u and "atomicCAS" in u for _, u in units)
    _compile_batch(units)


def test_fast_math_options_differ():
    assert "--use_fast_math" in nvrtc.options(ARCH, fast_math=True)
    ieee = nvrtc.options(ARCH)
    for flag in ("--ftz=false", "--prec-div=true", "--prec-sqrt=true", "--fmad=false"):
        assert flag in ieee
    assert "--use_fast_math" not in ieee


# -- shape of the generated code ------------------------------------------------------


@wp.kernel
def saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
    i = wp.tid()
    y[i] = a * x[i] + y[i]  # SAXPY-LINE


def _line_of(marker: str) -> int:
    with open(__file__) as f:
        return next(n for n, text in enumerate(f, 1) if marker in text and "_line_of" not in text)


def test_saxpy_holds_only_what_it_uses():
    src = lower(BACKEND, saxpy.build_module(), "cuda-c")
    assert "kd_vec" not in src and "kd_mat" not in src
    assert "atomic" not in src and "kd_f16" not in src and "#include" not in src
    assert "kd_fmin" not in src and "kd_idiv" not in src and "kd_err" not in src
    assert "kd_array1" in src and 'extern "C" __global__' in src


def test_line_directives_point_at_python_source():
    src = lower(BACKEND, saxpy.build_module(), "cuda-c")
    lines = src.splitlines()
    store = next(i for i, t in enumerate(lines) if "*(float *)kd_at1(" in t and "= " in t)
    # The nearest #line above the store names this file; counting lines from it gives
    # the Python line of the statement.
    k = store - 1
    while not lines[k].startswith("#line"):
        k -= 1
    m = re.match(r'#line (\d+) "(.*)"', lines[k])
    assert m and m.group(2) == __file__
    assert int(m.group(1)) + (store - k - 1) == _line_of("SAXPY-LINE")


KEYWORDS_IR = """\
struct template {new: f32, auto: i32, register: vec<3, f32>}

func.func @kd_fmin(%auto: f32, %new: f32) -> (f32) {kind = "func"} {
  %register = arith.add %auto, %new : f32
  func.return %register
}

func.func @auto(%new: array<f32, 1>, %template: struct<template>, %register: f32, %kd_i: i32) -> () {kind = "kernel"} {
  %i = kd.tid {dim = 0, ndim = 1} : i32
  %a = struct.extract %template {field = "new"} : f32
  %b = func.call %a, %register {callee = "kd_fmin"} : f32
  %c = arith.min %b, %a : f32
  %t2 = struct.insert %template, %c {field = "new"} : struct<template>
  %d = struct.extract %t2 {field = "new"} : f32
  kd.store %d, %new, %kd_i
  func.return
}
"""


def test_user_names_are_mangled():
    module = parse_module(KEYWORDS_IR)
    src = generate(module, ["auto"]).text
    code = "\n".join(t for t in src.splitlines() if not t.startswith("//"))
    for word in ("auto", "new", "template", "register"):
        assert not re.search(rf"\b{word}\b", code), word
    # The user's function named like a helper is not the helper.
    assert "k_kd_fmin_" in src and "__device__ __forceinline__ float kd_fmin(" in src
    nvrtc.compile_source(src, ARCH)


def test_packer_lays_out_struct_params_like_c():
    st = T.StructType("S", (("a", T.F64), ("b", T.F32)))  # 16 bytes: 4 bytes of tail padding
    p = Packer([T.F32, st, T.BOOL, T.VectorType(3, T.F32)], ["x", "s", "f", "v"], debug=True)
    # x at 0, s aligned to 8, f after s's 16 bytes, v aligned to 4, grid, record aligned to 8.
    assert p.offsets == [0, 8, 24, 28, 40, 64]

    class Arr:  # enough of a cupy array for the packer
        shape, strides, size = (4,), (8,), 4

        class data:
            ptr, device_id = 0x1000, 0

    buf, params = p.pack(
        [np.float32(1.5), (np.float64(2.0), np.float32(3.0)), np.bool_(True),
         np.array([4, 5, 6], np.float32)], 0, (10, 10, 1, 1, 1), record=0xABC,
    )  # fmt: skip
    raw = bytes(buf)
    assert np.frombuffer(raw[8:16], np.float64)[0] == 2.0
    assert np.frombuffer(raw[28:40], np.float32).tolist() == [4, 5, 6]
    assert np.frombuffer(raw[64:72], np.uint64)[0] == 0xABC
    assert len(params) == 6
    arr = Packer([T.ArrayType(T.F32, 1)], ["x"], debug=False)
    buf, _ = arr.pack([Arr()], 0, (4, 4, 1, 1, 1))
    assert np.frombuffer(bytes(buf)[:24], np.int64).tolist() == [0x1000, 4, 8]
    with pytest.raises(KdslError, match=r"cuda:0.*cuda:1"):
        arr.pack([Arr()], 1, (4, 4, 1, 1, 1))


# -- errors ---------------------------------------------------------------------------


@wp.kernel
def adds(x: wp.array(dtype=float)):
    i = wp.tid()
    x[i] = x[i] + 1.0  # ADD-LINE


def test_nvrtc_error_names_python_line(monkeypatch):
    monkeypatch.setitem(ops.TABLE, "arith.add", lambda em, op: "kd_no_such_helper()")
    with pytest.raises(KdslError) as info:
        compile_kernel(BACKEND, adds.build_module(), adds.key, {"arch": ARCH})
    text = str(info.value)
    assert "kd_no_such_helper" in text
    assert f'File "{__file__}", line {_line_of("ADD-LINE")}' in text
    assert "x[i] = x[i] + 1.0" in text


def test_nvrtc_error_in_generated_code_quotes_it():
    err = nvrtc.compile_error(
        'kdsl_module.cu(2): error: identifier "oops" is undefined', "int a;\nint b = oops;\n", None
    )
    assert "oops" in str(err) and "int b = oops;" in str(err)


# -- the backend ------------------------------------------------------------------------


def test_compile_without_gpu_for_a_given_arch_uses_the_cache():
    k1 = compile_kernel(BACKEND, saxpy.build_module(), saxpy.key, {"arch": ARCH})
    assert k1.payload.cubin(ARCH)[:4] == b"\x7fELF"
    k2 = compile_kernel(BACKEND, saxpy.build_module(), saxpy.key, {"arch": ARCH})
    assert k2.payload.job.key(ARCH) == k1.payload.job.key(ARCH)
    assert k2.payload.cubin(ARCH) is k1.payload.cubin(ARCH)  # the memory layer's object


def test_stages_and_ptx():
    assert BACKEND.stages() == ["kir", "kir-opt", "cuda-c", "ptx"]
    ptx = lower(BACKEND, saxpy.build_module(), "ptx", {"arch": ARCH})
    assert ".entry" in ptx and "sm_90" in ptx
    fast = lower(BACKEND, saxpy.build_module(), "ptx", {"arch": ARCH, "fast_math": True})
    assert ".entry" in fast
    with pytest.raises(KdslError, match="no stage"):
        lower(BACKEND, saxpy.build_module(), "llvm-ir")


def test_cli_prints_cuda_c(capsys):
    from kdsl.cli import main

    assert main(["ir", f"{__file__}:saxpy", "--backend", "cuda", "--stage", "cuda-c"]) == 0
    out = capsys.readouterr().out
    assert 'extern "C" __global__' in out and "#line" in out


def test_registered_and_lazy():
    from kdsl.backends.registry import get_backend

    assert get_backend("cuda").name == "cuda"
    assert {"fp16", "fp64", "int64", "atomics"} <= BACKEND.capabilities
    code = (
        "import sys, kdsl; from kdsl.backends.registry import get_backend; "
        "b = get_backend('cuda'); assert 'cupy' not in sys.modules, 'cupy imported'"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
