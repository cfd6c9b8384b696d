"""The thread loop's parallel-access metadata and the unrolled short loops (``loop_md``).

What the IR holds (kernel-array accesses in the kernel's access group, the thread
loop's ``llvm.loop.parallel_accesses``, a constant 4-trip neighbour loop emitted
unrolled; thread-local arrays, atomics and dynamic or long loops left alone), that
a gathering kernel then vectorizes, and that the results are those of a debug build
(which has neither: the very same bits), of the interpreter and of cuda, inline and
split over the pool, on dense and strided arrays.
"""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.backends.cpu import loop_md
from kdsl.compiler import lower
from tests.device_targets import TARGETS

NBR = 4


def _springs(
    x: wp.array(dtype=wp.vec3),
    nbr: wp.array(dtype=int),
    rest: wp.array(dtype=float),
    k: float,
    out: wp.array(dtype=wp.vec3),
):
    p = wp.tid()
    xp = x[p]
    f = wp.vec3(0.0, 0.0, 0.0)
    for s in range(4):
        q = nbr[p * 4 + s]
        if q >= 0:
            d = x[q] - xp
            length = wp.length(d)
            if length > 0.0:
                f = f + d / length * (k * (length - rest[p * 4 + s]))
    out[p] = f


springs = wp.kernel(_springs)
springs_debug = wp.kernel(debug=True)(_springs)


@wp.kernel
def dynamic_loop(x: wp.array(dtype=float), n: int, out: wp.array(dtype=float)):
    i = wp.tid()
    acc = 0.0
    for s in range(n):
        acc = acc + x[i] * float(s)
    out[i] = acc


@wp.kernel
def long_loop(x: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    acc = 0.0
    for s in range(17):
        acc = acc + x[i] * float(s)
    out[i] = acc


@wp.kernel
def with_atomic(x: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    acc = 0.0
    for s in range(4):
        acc = acc + x[i] * float(s)
    wp.atomic_add(out, i % 3, acc)


@wp.kernel
def with_local(x: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    scratch = wp.zeros(4, dtype=float)
    for s in range(4):
        scratch[s] = x[i] + float(s)
    out[i] = scratch[int(x[i]) % 4]


def _ir(kernel, stage: str = "llvm-ir-unopt") -> str:
    from kdsl.backends.cpu import BACKEND

    return lower(BACKEND, kernel.build_module(), stage)


def _thread_body(text: str) -> str:
    """The unoptimized IR from the thread loop's body on (the parameters load before it)."""
    return text.split("thread.body:", 1)[1]


def _accesses(text: str) -> list[str]:
    """The loads and stores among the lines of ``text``."""
    return [ln for ln in text.splitlines() if " = load " in ln or ln.lstrip().startswith("store ")]


def _host_has(feature: str) -> bool:
    import llvmlite.binding as llvm

    return bool(llvm.get_host_cpu_features().get(feature, False))


def test_array_accesses_join_the_group_and_the_thread_loop_is_parallel(cpu_backend):
    text = _ir(springs)
    assert "llvm.loop.parallel_accesses" in text
    accesses = _accesses(_thread_body(text))
    assert len(accesses) > 4 and all("!llvm.access.group" in ln for ln in accesses)
    assert "for.head" not in text  # the 4-trip neighbour loop is emitted unrolled


def test_debug_builds_claim_nothing(cpu_backend):
    from kdsl.backends.cpu.lower import lower_kernels

    module = springs_debug.build_module()
    text = str(lower_kernels(module, [springs_debug.key], debug=True).llmod)
    assert "parallel_accesses" not in text and "access.group" not in text
    assert "for.head" in text


@pytest.mark.parametrize("kernel", [dynamic_loop, long_loop, with_atomic],
                         ids=["dynamic", "long", "atomic"])  # fmt: skip
def test_loops_that_stay_loops(cpu_backend, kernel):
    assert "for.head" in _ir(kernel)


def test_thread_local_arrays_stay_out_of_the_group(cpu_backend):
    text = _ir(with_local)
    accesses = _accesses(_thread_body(text))
    tagged = [ln for ln in accesses if "access.group" in ln]
    # x[i] twice and out[i] join; the local array's store in the loop and load after do not
    assert len(tagged) == 3 and len(accesses) == 5
    assert "for.head" in text  # a kernel with a local array is not a parallel one


def test_predicates_on_the_ir():
    assert loop_md.thread_parallel(springs.build_module().get_func(springs.key))
    for kernel in (with_atomic, with_local):
        assert not loop_md.thread_parallel(kernel.build_module().get_func(kernel.key))
    loops = [op for op in long_loop.build_module().get_func(long_loop.key).walk()
             if op.name == "scf.for"]  # fmt: skip
    assert loops and loop_md.short_trips(loops[0]) is None


@pytest.mark.skipif(not _host_has("avx2"), reason="the vectorizer's choice depends on the host")
def test_a_gathering_kernel_vectorizes(cpu_backend):
    text = _ir(springs, "llvm-ir")
    assert "vector.body" in text and "llvm.masked.gather" in text


def _cloth(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions, a neighbour list with holes (-1) and repeated points, rest lengths."""
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((n, 3)).astype(np.float32)
    x[5] = x[4]  # a zero-length spring
    nbr = rng.integers(-1, n, size=(n, NBR)).astype(np.int32)
    nbr[4, 0] = 5
    rest = rng.uniform(0.1, 1.0, size=(n, NBR)).astype(np.float32)
    return x, nbr.ravel(), rest.ravel()


def _run(kernel, x, nbr, rest, dev="cpu", backend=None, x_array=None) -> np.ndarray:
    n = len(x)
    xa = x_array if x_array is not None else wp.array(x, dtype=wp.vec3, device=dev)
    out = wp.zeros(n, dtype=wp.vec3, device=dev)
    wp.launch(kernel, n, [xa, wp.array(nbr, device=dev), wp.array(rest, device=dev), 3.5, out],
              device=dev, backend=backend)  # fmt: skip
    return out.numpy()


def test_same_bits_as_a_debug_build(split):
    x, nbr, rest = _cloth(1003)  # not a multiple of any vector width
    got, want = _run(springs, x, nbr, rest), _run(springs_debug, x, nbr, rest)
    np.testing.assert_array_equal(got.view(np.uint32), want.view(np.uint32))


def test_strided_arrays_give_the_dense_result(split):
    x, nbr, rest = _cloth(515, seed=1)
    wide = np.zeros((len(x), 2, 3), np.float32)
    wide[:, 0] = x
    every_other = wp.array(wide.reshape(-1, 3), dtype=wp.vec3)[::2]
    got = _run(springs, x, nbr, rest, x_array=every_other)
    np.testing.assert_array_equal(got.view(np.uint32), _run(springs, x, nbr, rest).view(np.uint32))


@pytest.mark.parametrize(("dev", "backend"), TARGETS)
def test_results_on_every_target(dev, backend, split):
    x, nbr, rest = _cloth(777, seed=2)
    expect = np.zeros_like(x, dtype=np.float64)
    for p in range(len(x)):
        for s in range(NBR):
            q = nbr[p * NBR + s]
            if q >= 0:
                d = x[q].astype(np.float64) - x[p]
                length = np.linalg.norm(d)
                if length > 0.0:
                    expect[p] += d / length * (3.5 * (length - rest[p * NBR + s]))
    got = _run(springs, x, nbr, rest, dev, backend)
    np.testing.assert_allclose(got, expect, rtol=2e-5, atol=2e-5)
