"""``kd.prefetch`` (``kdsl.ir.ops_prefetch``): a hint with no visible effect.

Every pass keeps it; the cpu backend lowers it to one ``llvm.prefetch`` per cache line
the element may touch; the interpreter and the cuda backend do nothing; a kernel that
prefetches computes what it computes without (also for an index out of range, which a
prefetch may name); bad arguments are located errors."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.backends.cpu.prefetch import line_offsets
from kdsl.errors import KdslTypeError, KdslVerifyError
from kdsl.frontend.builtins_prefetch import PREFETCH
from kdsl.ir import parse_module, print_module
from kdsl.passes import DEFAULT_PIPELINE, run_pipeline


@wp.struct
class Big:
    a: wp.mat44
    b: wp.mat44
    c: wp.vec4


@wp.kernel
def ahead(xs: wp.array(dtype=Big), out: wp.array(dtype=float)):
    i = wp.tid()
    PREFETCH(xs, i + 1)  # the last thread's is past the end: a hint, never a fault
    out[i] = xs[i].c[2] + xs[i].a[1, 1]


@wp.kernel
def ahead_2d(xs: wp.array2d(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    PREFETCH(xs, i, 0)
    out[i] = xs[i, 1]


def _optimized(kernel):
    m = kernel.build_module()
    run_pipeline(m, DEFAULT_PIPELINE)
    return m


def _bigs(n: int):
    rng = np.random.default_rng(5)
    view = wp.zeros(n, dtype=Big).numpy()
    view["c"] = rng.uniform(-1, 1, (n, 4)).astype(np.float32)
    view["a"] = rng.uniform(-1, 1, (n, 4, 4)).astype(np.float32)
    return wp.array(view, dtype=Big), view


@pytest.mark.parametrize("backend", ["interp", "cpu"])
def test_a_prefetching_kernel_computes_the_same(backend):
    xs, view = _bigs(37)
    out = wp.zeros(37, dtype=float)
    wp.launch(ahead, dim=37, inputs=[xs, out], backend=backend)
    np.testing.assert_array_equal(out.numpy(), view["c"][:, 2] + view["a"][:, 1, 1])
    m = np.arange(12, dtype=np.float32).reshape(6, 2)
    out2 = wp.zeros(6, dtype=float)
    wp.launch(ahead_2d, dim=6, inputs=[wp.array(m, dtype=float), out2], backend=backend)
    np.testing.assert_array_equal(out2.numpy(), m[:, 1])


def test_passes_keep_it():
    assert "kd.prefetch" in print_module(_optimized(ahead))


def test_line_offsets_reach_every_line():
    assert line_offsets(4) == [0, 3]
    assert line_offsets(64) == [0, 63]
    assert line_offsets(144) == [0, 64, 128, 143]
    for size in (1, 16, 63, 65, 128, 160, 300):
        offs = line_offsets(size)
        for start in range(64):  # every alignment: each line the element touches is hit
            touched = set(range(start // 64, (start + size - 1) // 64 + 1))
            assert {(start + o) // 64 for o in offs} == touched, (size, start)


def test_cpu_prefetches_each_line():
    from kdsl.backends.cpu import BACKEND
    from kdsl.compiler import lower

    size = 2 * 64 + 16  # Big: two mat44 and a vec4, 144 bytes
    text = lower(BACKEND, ahead.build_module(), "llvm-ir-unopt", None)
    calls = [ln for ln in text.splitlines() if "call" in ln and "llvm.prefetch" in ln]
    assert len(calls) == len(line_offsets(size)), calls


def test_cuda_emits_nothing_for_it():
    pytest.importorskip("cupy_backends.cuda.libs.nvrtc")
    from kdsl.backends.cuda import nvrtc
    from kdsl.backends.cuda.lower import generate

    src = generate(_optimized(ahead), [ahead.key]).text
    assert src.count("prefetch") == src.count("test_prefetch")  # the file name only
    nvrtc.compile_source(src, "sm_90")


def test_bad_arguments_are_located_errors():
    @wp.kernel
    def not_an_array(x: float, out: wp.array(dtype=float)):
        PREFETCH(x, 0)

    @wp.kernel
    def too_few(xs: wp.array2d(dtype=float), out: wp.array(dtype=float)):
        PREFETCH(xs, 0)

    out = wp.zeros(1, dtype=float)
    with pytest.raises(KdslTypeError, match="needs an array first") as e:
        wp.launch(not_an_array, dim=1, inputs=[1.0, out], backend="interp")
    assert "test_prefetch.py" in str(e.value) and "PREFETCH(x, 0)" in str(e.value)
    with pytest.raises(KdslTypeError, match="needs 2 indices, got 1"):
        wp.launch(too_few, dim=1, inputs=[wp.zeros((2, 2), dtype=float), out],
                  backend="interp")  # fmt: skip


def test_the_verifier_checks_its_operands():
    text = (
        'func.func @f(%0: f32) -> () {kind = "func"} {\n'
        "  %1 = arith.constant {value = 0} : i32\n"
        "  kd.prefetch %0, %1\n"
        "  func.return\n}\n"
    )
    with pytest.raises(KdslVerifyError, match=r"kd\.prefetch takes an array"):
        parse_module(text, file="t.kir")
