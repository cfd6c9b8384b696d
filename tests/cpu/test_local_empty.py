"""``kdsl.ext.empty(shape, dtype)``: a thread-local array without the zero fill
(``kd.local_array`` with ``fill = "none"``), on interp and cpu (and cuda: compile-only
through NVRTC here, run on a GPU when one is present), its poison pattern on interp, the
IR text form, and its errors. The adjoint around one and a stack's pushes and pops:
tests/cpu/test_local_arrays.py."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.backends import registry
from kdsl.compiler import lower
from kdsl.errors import KdslError, KdslTypeError
from kdsl.ir import parse_module, print_module
from kdsl.ir.ops_local import POISON_BYTE
from tests.cpu.test_local_arrays import make_stack_digits

BACKENDS = ["interp", "cpu"]
POISON_I32 = int(np.full(4, POISON_BYTE, np.uint8).view(np.int32)[0])


@pytest.fixture(params=BACKENDS)
def backend(request, cpu_backend):
    return request.param


#: A stack pushed before it is popped: no element is read before it is written.
stack_digits = make_stack_digits(wp.ext.empty)


@wp.func
def fill_rows(m: wp.array2d(dtype=wp.vec2), x: float):
    for a in range(m.shape[0]):
        for b in range(m.shape[1]):
            m[a, b] = wp.vec2(x * float(a), float(b))


@wp.kernel
def written_by_a_func(x: wp.array(dtype=float), out: wp.array(dtype=float)):
    # A 2-d array of vectors written whole by a @func, then read; keywords as zeros's.
    i = wp.tid()
    m = wp.ext.empty(shape=(3, 2), dtype=wp.vec2)
    fill_rows(m, x[i])
    out[i] = m[2, 0][0] + m[1, 1][1] + float(m.shape[0])


def test_2d_written_by_a_func(backend):
    x = np.array([1.0, -2.0, 0.5], dtype=np.float32)
    out = wp.zeros(3, dtype=float)
    wp.launch(written_by_a_func, 3, [wp.array(x), out], backend=backend)
    np.testing.assert_allclose(out.numpy(), 2.0 * x + 1.0 + 3.0)


@wp.kernel
def read_first(f: wp.array(dtype=float), k: wp.array(dtype=int), v: wp.array(dtype=wp.vec3)):
    # Reads before any write: undefined contents (the poison pattern on interp).
    i = wp.tid()
    a = wp.ext.empty(4, dtype=float)
    b = wp.ext.empty(4, dtype=int)
    c = wp.ext.empty(2, dtype=wp.vec3)
    f[i] = a[i]
    k[i] = b[i]
    v[i] = c[i]


def test_interp_poisons_reads_before_writes():
    f, k, v = wp.zeros(2, dtype=float), wp.zeros(2, dtype=int), wp.zeros(2, dtype=wp.vec3)
    wp.launch(read_first, 2, [f, k, v], backend="interp")
    assert np.isnan(f.numpy()).all() and np.isnan(v.numpy()).all()
    np.testing.assert_array_equal(k.numpy(), [POISON_I32, POISON_I32])


@wp.struct
class Pair:
    n: wp.int32
    x: wp.float32


@wp.kernel
def read_struct(n: wp.array(dtype=int), x: wp.array(dtype=float)):
    i = wp.tid()
    s = wp.ext.empty(2, dtype=Pair)
    n[i] = s[i].n
    x[i] = s[i].x


def test_interp_poisons_struct_fields_by_kind():
    n, x = wp.zeros(1, dtype=int), wp.zeros(1, dtype=float)
    wp.launch(read_struct, 1, [n, x], backend="interp")
    assert n.numpy()[0] == POISON_I32 and np.isnan(x.numpy()[0])


@wp.kernel
def fresh_each_run(out: wp.array(dtype=float)):
    # A zeros() in the same loop still gives zeros: only ext.empty skips the fill.
    i = wp.tid()
    total = 0.0
    for k in range(3):
        z = wp.zeros(2, dtype=float)
        e = wp.ext.empty(2, dtype=float)
        e[0] = float(k)
        e[1] = 1.0
        total += z[0] + z[1] + e[0] * e[1]
        z[k % 2] = 5.0
    out[i] = total


def test_zeros_beside_empty(backend):
    out = wp.zeros(2, dtype=float)
    wp.launch(fresh_each_run, 2, [out], backend=backend)
    np.testing.assert_array_equal(out.numpy(), [3.0, 3.0])


# --- the IR and the lowerings ------------------------------------------------------------


def test_ir_text_round_trips():
    text = lower(registry.get_backend("interp"), stack_digits, "kir-opt")
    assert 'kd.local_array {fill = "none", shape = [8]} : array<i32, 1>' in text
    once = print_module(parse_module(text))
    assert 'fill = "none"' in once and print_module(parse_module(once)) == once
    zeros = lower(registry.get_backend("interp"), fresh_each_run, "kir-opt")
    assert "kd.local_array {shape = [2]}" in zeros  # zeros print without the attribute


def test_verifier_refuses_an_unknown_fill():
    text = lower(registry.get_backend("interp"), stack_digits, "kir-opt")
    with pytest.raises(KdslError, match="fill must be one of"):
        parse_module(text.replace('fill = "none"', 'fill = "ones"'))


def test_cpu_emits_no_memset(cpu_backend):
    ir_empty = lower(cpu_backend, stack_digits, "llvm-ir")
    assert "alloca" in ir_empty and "llvm.memset" not in ir_empty
    ir_zeros = lower(cpu_backend, fresh_each_run, "llvm-ir")
    assert "alloca" not in ir_zeros  # zeros still fill: promoted to registers as constants


def _cuda_unit(kernel) -> str:
    from kdsl.backends.cuda.lower import generate
    from kdsl.passes import DEFAULT_PIPELINE, run_pipeline

    m = kernel.build_module()
    run_pipeline(m, DEFAULT_PIPELINE)
    return generate(m, [kernel.key]).text


def test_cuda_emits_no_fill_and_compiles():
    pytest.importorskip("cupy_backends.cuda.libs.nvrtc")
    from kdsl.backends.cuda import nvrtc

    unit = _cuda_unit(stack_digits)
    assert "_s[8];" in unit and "] = {};" not in unit
    assert "] = {};" in _cuda_unit(fresh_each_run)
    ptx = nvrtc.compile_source(unit, "sm_90").ptx
    assert "st.local" in ptx  # the pushes: the stack is in local memory, never filled


@pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA GPU")
def test_cuda_stack_push_pop():
    n = np.array([0, 7, 12, 345, 1000, 98765], dtype=np.int32)
    out = wp.zeros(len(n), dtype=int, device="cuda:0")
    wp.launch(stack_digits, len(n), [wp.array(n, device="cuda:0"), out], device="cuda:0")
    np.testing.assert_array_equal(out.numpy(), n)
    x = np.array([1.0, -2.0, 0.5], dtype=np.float32)
    got = wp.zeros(3, dtype=float, device="cuda:0")
    wp.launch(written_by_a_func, 3, [wp.array(x, device="cuda:0"), got], device="cuda:0")
    np.testing.assert_allclose(got.numpy(), 2.0 * x + 4.0)


# --- errors ------------------------------------------------------------------------------


def _compile(fn):
    return wp.launch(wp.kernel(fn), 1, [wp.zeros(1, dtype=float)], backend="interp")


def test_shape_must_be_constant():
    def k(out: wp.array(dtype=float)):
        n = out.shape[0]
        a = wp.ext.empty(n, dtype=float)
        out[0] = a[0]

    with pytest.raises(KdslTypeError, match=r"ext.empty\(\) in a kernel .* compile-time") as info:
        _compile(k)
    loc = info.value.loc
    assert loc is not None and loc.line == k.__code__.co_firstlineno + 2
    assert "wp.ext.empty(n" in str(info.value)  # the source line is shown


@pytest.mark.parametrize("dtype", ["array", "str"])
def test_bad_dtype(dtype):
    bad = wp.array(dtype=float) if dtype == "array" else str

    def k(out: wp.array(dtype=float)):
        a = wp.ext.empty(4, dtype=bad)
        out[0] = a[0]

    with pytest.raises(KdslTypeError, match=r"ext\.empty\(\)") as info:
        _compile(k)
    assert info.value.loc is not None and info.value.loc.line == k.__code__.co_firstlineno + 1


def test_too_large_and_missing_shape():
    def big(out: wp.array(dtype=float)):
        a = wp.ext.empty((200, 200), dtype=float)
        out[0] = a[0, 0]

    with pytest.raises(KdslTypeError, match="160000 bytes, over the limit of 65536"):
        _compile(big)

    def no_shape(out: wp.array(dtype=float)):
        a = wp.ext.empty(dtype=float)
        out[0] = a[0]

    with pytest.raises(KdslTypeError, match=r"ext\.empty\(\) needs a shape"):
        _compile(no_shape)


def test_python_scope_is_refused():
    with pytest.raises(KdslError, match="kernel builtin only"):
        wp.ext.empty(4, dtype=float)
