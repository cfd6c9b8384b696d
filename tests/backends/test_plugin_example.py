"""The example backend plugin in examples/plugin_backend, used as a third party would.

The plugin is not pip-installed here: its directory goes on ``sys.path`` and the backend
is registered with ``register_backend``; both are undone afterwards. It must compile and
launch kernels through the public plugin interface, cache its generated source in the
kernel cache, print its "python" stage, and pass a sample of the conformance suite (the
whole suite: ``kdsl conformance --backend pyexec`` once it is installed).
"""

import ast
import sys
from pathlib import Path

import numpy as np
import pytest

import kdsl as wp
from kdsl.backends import registry
from kdsl.compiler import compile_kernel, lower
from kdsl.compiler.cache import DiskCache, cache_dir
from kdsl.errors import KdslError, KdslRuntimeError
from kdsl.ir import parse_module
from kdsl.testing.cases import all_cases
from kdsl.testing.conformance import check_case

PLUGIN_DIR = Path(__file__).resolve().parents[2] / "examples" / "plugin_backend"
PACKAGE = PLUGIN_DIR / "kdsl_pyexec"


@pytest.fixture(scope="module")
def pyexec():
    """The plugin's backend, registered for this module's tests only."""
    was_installed = registry.is_registered("pyexec")  # e.g. pip install -e of the example
    registry.unregister_backend("pyexec")
    sys.path.insert(0, str(PLUGIN_DIR))
    try:
        from kdsl_pyexec import BACKEND

        yield registry.register_backend(BACKEND)
    finally:
        registry.unregister_backend("pyexec")
        sys.path.remove(str(PLUGIN_DIR))
        for name in [m for m in sys.modules if m.split(".")[0] == "kdsl_pyexec"]:
            del sys.modules[name]
        if was_installed:
            registry.reset_registry()  # rediscover the installed entry point


@wp.func
def clamp_sq(x: float, hi: float):
    y = x * x
    if y > hi:
        return hi
    return y


@wp.kernel
def loops(a: wp.array2d(dtype=float), out: wp.array2d(dtype=float), n: int):
    i, j = wp.tid()
    s = 0.0
    for k in range(n):
        s = s + clamp_sq(a[i, j] + float(k), 50.0)
    k = 0
    while k < 3:
        k += 1
        s += 1.0
    out[i, j] = s


def test_only_public_kdsl_imports():
    """The plugin imports kdsl's plugin API only, never the runtime, frontend or driver."""
    allowed = {"kdsl.backends.base", "kdsl.errors", "kdsl.ir", "kdsl.ir.catalog"}
    for path in PACKAGE.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else []
            if isinstance(node, ast.ImportFrom) and node.level == 0:
                names = [node.module or ""]
            for name in names:
                if name.split(".")[0] == "kdsl":
                    assert name in allowed, f"{path.name} imports {name}"


def test_identity_and_stages(pyexec):
    assert registry.get_backend("pyexec") is pyexec
    assert pyexec.stages() == ["kir", "kir-opt", "python"]
    assert pyexec.serves("cpu") and not pyexec.serves("cuda:0")


def test_python_stage_is_structured_source(pyexec):
    text = lower(pyexec, loops, "python")
    ast.parse(text)  # valid Python
    assert "for _i" in text and "while True:" in text and "if " in text
    assert 'CATALOG["arith.add"].interp' in text  # op semantics come from the catalog
    assert "kd.load @ test_plugin_example.py:" in text  # each op line names its source
    with pytest.raises(KdslError, match="no stage 'ptx'"):
        lower(pyexec, loops, "ptx")


def test_launch_loops_and_calls(pyexec):
    a_np = np.arange(12, dtype=np.float32).reshape(3, 4) * 0.5
    a, out = wp.array(a_np), wp.zeros((3, 4), dtype=float)
    wp.launch(loops, dim=(3, 4), inputs=[a, out, 4], backend="pyexec")
    want = sum(np.minimum((a_np + k) ** 2, 50.0) for k in range(4)) + 3.0
    np.testing.assert_allclose(out.numpy(), want, rtol=1e-6)


def test_generated_source_is_the_cached_artifact(pyexec):
    compiled = compile_kernel(pyexec, loops)
    key = compiled.metadata["cache_key"]
    stored = DiskCache(cache_dir()).load(key)
    if stored is None:
        pytest.skip("the disk kernel cache is off in this environment")
    assert stored.decode() == lower(pyexec, loops, "python")
    again = compile_kernel(pyexec, loops)  # same IR: the same key, the loaded code object
    assert again.metadata["cache_key"] == key and again.payload.fn is not compiled.payload.fn


def test_errors_name_the_thread_and_the_op(pyexec):
    src = (
        'func.func @k(%a: array<f32, 1>, %b: array<f32, 1>) -> () {kind = "kernel"} {\n'
        "  %i = kd.tid {dim = 0, ndim = 1} : i32\n"
        "  %v = kd.load %a, %i : f32\n"
        "  kd.store %v, %b, %i\n"
        "  func.return\n}\n"
    )
    compiled = compile_kernel(pyexec, parse_module(src), "k")
    a, b = np.arange(4, dtype=np.float32), np.zeros(3, np.float32)
    with pytest.raises(KdslRuntimeError, match="out of bounds") as info:
        pyexec.launch(compiled, (4,), [a, b])
    assert "in thread 3 of kernel 'k'" in str(info.value)
    np.testing.assert_array_equal(b, [0, 1, 2])  # threads before the bad one ran
    # A Python exception inside a rule is traced back to its op's line of generated code.
    with pytest.raises(KdslRuntimeError, match=r"the pyexec backend failed on kd\.load"):
        pyexec.launch(compiled, (1,), [None, b])


#: A sample of the conformance suite, one or two cases per group.
SAMPLE = [
    "arith_add_f32", "compare_i32", "math_sin_f32", "vec_dot_cross", "mat_mat",
    "for_negative_step", "while_data_dependent", "loop_break", "func_multiple_returns",
    "func_early_return_in_loop", "tid_3d", "atomic_add_contention", "program_matmul",
    "struct_through_funcs_f32", "struct_branch_merge_f32", "grad_sin",
]  # fmt: skip


@pytest.mark.parametrize("name", SAMPLE)
def test_conformance_sample(pyexec, name):
    (case,) = [c for c in all_cases() if c.name == name]
    check_case(case, "pyexec")
