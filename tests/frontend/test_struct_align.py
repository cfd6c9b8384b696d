"""``@kdsl.struct(align=N)``: a declared struct alignment in the dtype table, its layout
everywhere (NumPy, records, CUDA C, kernel parameters), the arrays it accepts, kernels
reading and writing it, and the 16-byte vector loads the cuda backend gets from it."""

import re

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslError, KdslTypeError
from kdsl.ir import types as T

BACKENDS = ["interp", "cpu"]


@wp.struct(align=16)
class Half:  # 12 + 4 bytes: Warp's BVH node half
    lower: wp.vec3
    first: wp.int32


@wp.struct(align=16)
class Small:  # 4 bytes of fields, padded to 16
    x: float


@wp.struct
class Outer:  # a natural struct holding an aligned one: ``s`` moves to offset 16
    a: wp.int8
    s: Small
    b: float


@wp.struct
class Natural:  # the same fields as Small, no declared alignment
    x: float


def test_storage_layout_pads_and_aligns():
    assert Half.numpy_dtype().itemsize == 16
    assert Small.numpy_dtype().itemsize == 16 and Natural.numpy_dtype().itemsize == 4
    dt = Outer.numpy_dtype()
    assert dt.fields["s"][1] == 16 and dt.fields["b"][1] == 32 and dt.itemsize == 48
    assert T.alignment(Outer.__kdsl_type__) == 16 and T.alignment(Natural.__kdsl_type__) == 4
    assert Small.__kdsl_type__ != Natural.__kdsl_type__  # the alignment is part of the type


def test_records_and_kernel_parameters_agree_with_the_storage_layout():
    from kdsl.backends.cuda import ctypes_ as CT
    from kdsl.ir.records import record_dtype

    for cls in (Half, Small, Outer):
        st, dt = cls.__kdsl_type__, cls.numpy_dtype()
        assert record_dtype(st) == dt
        assert CT.layout(st) == (dt.itemsize, T.alignment(st))


def test_the_ir_text_form_keeps_the_alignment():
    from kdsl.ir import parse_module, print_module

    m = read_halves.build_module()
    text = print_module(m)
    name = Half.__kdsl_type__.name
    assert re.search(rf"^struct {name} align 16 \{{lower: vec<3, f32>, first: i32\}}", text, re.M)
    again = parse_module(text)
    assert print_module(again) == text
    assert again.structs[name].align == 16


@pytest.mark.parametrize("bad", [3, 0, 512, True, "16", 1.0])
def test_a_bad_alignment_is_a_clear_error(bad):
    with pytest.raises(KdslTypeError, match="align must be a power of two") as e:

        @wp.struct(align=bad)
        class Bad:  # BAD-ALIGN
            x: float

    assert e.value.loc is not None and e.value.loc.file == __file__


def test_arrays_refuse_misaligned_addresses_and_strides():
    a = wp.zeros(4, dtype=Half)
    assert a.ptr % 16 == 0 and a.strides == (16,)
    buf = wp.zeros(80, dtype=wp.uint8)
    base = buf.ptr + (-buf.ptr) % 16
    ok = wp.array(ptr=base, dtype=Half, shape=(2,), device="cpu")
    assert ok.shape == (2,)
    with pytest.raises(KdslError, match=r"declared align=16.*multiples of 16"):
        wp.array(ptr=base + 4, dtype=Half, shape=(2,), device="cpu")
    with pytest.raises(KdslError, match="multiples of 16"):
        wp.array(ptr=base, dtype=Half, shape=(2,), strides=(24,), device="cpu")
    assert wp.array(ptr=base + 4, dtype=Half, shape=(0,), device="cpu").size == 0
    assert a[1:3].shape == (2,) and a[::2].strides == (32,)  # views stay aligned


@wp.kernel
def read_halves(h: wp.array(dtype=Half), out: wp.array(dtype=wp.vec3), n: wp.array(dtype=int)):
    i = wp.tid()
    v = h[i]
    out[i] = v.lower * 2.0
    n[i] = v.first + 1


@wp.kernel
def write_outer(o: wp.array(dtype=Outer)):
    i = wp.tid()
    v = Outer()
    v.a = wp.int8(i)
    v.s.x = float(i) * 0.5
    v.b = float(i) + 10.0
    o[i] = v


def _halves(n: int, device: str):
    data = np.zeros(n, dtype=Half.numpy_dtype())
    data["lower"] = np.arange(3 * n, dtype=np.float32).reshape(n, 3)
    data["first"] = np.arange(n) * 7
    return wp.array(data, dtype=Half, device=device)


def _check_kernels(backend: str, device: str) -> None:
    n = 5
    out = wp.zeros(n, dtype=wp.vec3, device=device)
    k = wp.zeros(n, dtype=int, device=device)
    wp.launch(read_halves, n, [_halves(n, device), out, k], device=device, backend=backend)
    np.testing.assert_array_equal(out.numpy(), 2 * np.arange(3 * n).reshape(n, 3))
    np.testing.assert_array_equal(k.numpy(), np.arange(n) * 7 + 1)
    o = wp.zeros(n, dtype=Outer, device=device)
    wp.launch(write_outer, n, [o], device=device, backend=backend)
    got = o.numpy()
    np.testing.assert_array_equal(got["a"], np.arange(n))
    np.testing.assert_array_equal(got["s"]["x"], np.arange(n) * 0.5)
    np.testing.assert_array_equal(got["b"], np.arange(n) + 10.0)


@pytest.mark.parametrize("backend", BACKENDS)
def test_kernels_read_and_write_aligned_structs(backend):
    _check_kernels(backend, "cpu")


@pytest.mark.cuda
@pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")
def test_cuda_kernels_read_and_write_aligned_structs():
    _check_kernels("cuda", "cuda:0")


def _ptx_loads(kernel) -> list[str]:
    from kdsl.backends.cuda import nvrtc
    from kdsl.backends.cuda.lower import generate, without_fast_entries
    from kdsl.passes import DEFAULT_PIPELINE, run_pipeline

    m = kernel.build_module()
    run_pipeline(m, DEFAULT_PIPELINE)
    src = without_fast_entries(generate(m, [kernel.key]).text)  # the general entry alone
    return src, re.findall(r"\bld\.[\w.]+", nvrtc.compile_source(src, "sm_90").ptx)


def test_cuda_loads_an_aligned_struct_with_vector_loads():
    """Compile-only: the node of ``kdsl.stdlib.bvh`` and a 16-byte half load as ``ld.v4``
    (without ``align`` NVRTC reads them a 4-byte word at a time)."""
    pytest.importorskip("cupy_backends.cuda.libs.nvrtc")
    from kdsl.stdlib.bvh import BvhNode

    src, loads = _ptx_loads(read_halves)
    assert f"struct __align__(16) k_{Half.__kdsl_type__.name}_" in src
    assert any(ld.startswith("ld.v4") or ld.startswith("ld.global.v4") for ld in loads), loads

    @wp.kernel
    def read_natural(h: wp.array(dtype=Natural), out: wp.array(dtype=float)):
        out[wp.tid()] = h[wp.tid()].x

    _, plain = _ptx_loads(read_natural)
    assert not any(".v4" in ld for ld in plain)

    @wp.kernel
    def sum_nodes(nodes: wp.array(dtype=BvhNode), out: wp.array(dtype=float)):
        i = wp.tid()
        v = nodes[i]
        out[i] = v.lower[0] + v.upper[2] + float(v.first + v.next)

    _, node_loads = _ptx_loads(sum_nodes)
    assert sum(".v4" in ld for ld in node_loads) == 2, node_loads
