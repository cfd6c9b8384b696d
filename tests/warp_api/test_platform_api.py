"""Warp's error names, build options, allocators, memory tracking and CUDA queries."""

import io

import numpy as np
import pytest

import kdsl as wp

needs_cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")


@wp.kernel
def _bad_attribute(a: wp.array(dtype=wp.vec3)):
    a[0] = wp.vec3(a[0].w, 0.0, 0.0)


@wp.kernel
def _scale(a: wp.array(dtype=float)):
    i = wp.tid()
    a[i] = a[i] * 2.0


def test_warp_codegen_errors_catch_kdsl_errors():
    a = wp.zeros(1, dtype=wp.vec3)
    for cls in (wp.WarpCodegenError, wp.WarpCodegenAttributeError, wp.WarpCodegenTypeError,
                AttributeError):  # fmt: skip
        with pytest.raises(cls, match=r"no component '\.w'"):
            wp.launch(_bad_attribute, 1, [a])
    assert issubclass(wp.WarpCodegenIndexError, IndexError)
    assert issubclass(wp.WarpCodegenKeyError, KeyError)
    assert issubclass(wp.WarpCodegenValueError, ValueError)
    assert str(wp.WarpCodegenKeyError("no such stage")) == "no such stage"


def test_deterministic_mode_and_build_options(tmp_path):
    wp.set_module_options({"deterministic": wp.DeterministicMode.NOT_GUARANTEED})
    with pytest.raises(wp.WarpDeterminismError, match="no ordered-atomics mode"):
        wp.set_module_options({"deterministic": wp.DeterministicMode.RUN_TO_RUN})
    with pytest.raises(wp.KdslTypeError, match="DeterministicMode"):
        wp.set_module_options({"deterministic": "yes"})
    dep = tmp_path / "table.txt"
    dep.write_text("1")
    opts = wp.ModuleBuildOptions(extra_build_dependencies=[str(dep)])
    m = wp.get_module("tests.warp_api.build_options_probe")
    m.set_options({"extra_build_options": opts})
    before = m.compile_options()["build_dependencies"]
    dep.write_text("2")
    assert m.compile_options()["build_dependencies"] != before  # the contents key the build
    with pytest.raises(wp.KdslCapabilityError, match="extra_cpu_preamble"):
        m.set_options({"extra_build_options": wp.ModuleBuildOptions(extra_cpu_preamble="int x;")})
    with pytest.raises(wp.KdslValueError, match="absolute"):
        wp.ModuleBuildOptions(extra_build_dependencies=["relative.h"])
    with pytest.raises(wp.KdslTypeError, match="must be a str"):
        wp.ModuleBuildOptions(extra_cuda_preamble=3)
    merged = opts.merged(wp.ModuleBuildOptions(extra_build_dependencies=[str(dep)]))
    assert len(merged.extra_build_dependencies) == 2
    assert wp.JaxModulePreloadMode.ALL_DEVICES == 2


def test_memory_tracker_counts_kdsl_allocations():
    reports = []
    with wp.ScopedMemoryTracker("outer", report_func=reports.append):
        a = wp.zeros(1000, dtype=float, device="cpu")
        with wp.ScopedMemoryTracker("inner", report_func=reports.append):
            b = wp.ones((10, 10), dtype=wp.float64, device="cpu")
            out = io.StringIO()
            wp.print_memory_report(out, sort="chronological")
            assert "live on cpu: 4.7 KiB" in out.getvalue()  # 4000 + 800 bytes
            assert "outer/inner" in out.getvalue() and "test_platform_api.py" in out.getvalue()
        del b
    del a
    assert "scope outer/inner: 1 allocations, 800 B allocated" in reports[0]
    assert "scope outer: 1 allocations, 3.9 KiB allocated" in reports[1]
    with pytest.raises(wp.KdslError, match="not active"):
        wp.print_memory_report()
    with wp.ScopedMemoryTracker("x", print=False), pytest.raises(wp.KdslValueError, match="sort"):
        wp.print_memory_report(sort="name")


def test_allocators_on_the_cpu():
    host = wp.get_device_allocator("cpu")
    ptr = host.allocate(64)
    assert ptr != 0 and isinstance(host, wp.Allocator)
    host.deallocate(ptr, 64)
    with pytest.raises(wp.KdslError, match="CUDA devices only"):
        wp.set_device_allocator("cpu", wp.CudaManagedAllocator())
    with pytest.raises(wp.KdslTypeError, match="Allocator protocol"):
        wp.ScopedAllocator("cpu", object())
    a = wp.zeros(4, dtype=float, device="cpu")
    assert wp.can_access("cpu", a)
    with pytest.raises(wp.KdslTypeError, match="kdsl array"):
        wp.can_access("cpu", np.zeros(3))


def test_device_queries_and_profiler_without_cuda():
    if not wp.is_cuda_available():
        assert wp.get_cuda_driver_version() is None
        assert wp.get_cuda_toolkit_version() is None
        assert wp.get_cuda_supported_archs() == []
    with pytest.raises(wp.KdslError, match="not a CUDA device"):
        wp.get_cuda_kernel_properties(_scale, "cpu")
    with pytest.raises(wp.KdslTypeError, match=r"@kdsl\.kernel"):
        wp.get_suggested_block_size(print, "cpu")
    with wp.ScopedCudaProfiler("cpu"):  # a no-op on the cpu
        pass
    wp.clear_lto_cache()
    info = wp.print_diagnostics()
    assert info["devices"][0] == "cpu" and "llvmlite" in info


def test_handle_is_uint64():
    @wp.kernel
    def copy_handle(h: wp.handle, out: wp.array(dtype=wp.uint64)):
        out[0] = h

    out = wp.zeros(1, dtype=wp.uint64)
    wp.launch(copy_handle, 1, [wp.uint64(2**40 + 7), out])
    assert out.numpy()[0] == 2**40 + 7


@needs_cuda
def test_cuda_queries_and_custom_allocator():
    assert wp.get_cuda_driver_version()[0] >= 11
    assert wp.get_cuda_supported_archs()
    props = wp.get_cuda_kernel_properties(_scale, "cuda:0")
    assert props["register_count"] > 0 and props["local_memory_size"] >= 0
    block, grid = wp.get_suggested_block_size(_scale, "cuda:0")
    assert block > 0 and grid > 0
    assert wp.get_cuda_max_cluster_dim(_scale, "cuda:0") in (1, 8)
    with wp.ScopedCudaProfiler("cuda:0"):
        pass
    managed = wp.CudaManagedAllocator()
    with wp.ScopedAllocator("cuda:0", managed):
        a = wp.full(16, 3.0, dtype=float, device="cuda:0")
    assert wp.get_device_allocator("cuda:0") is not managed
    assert wp.can_access("cpu", a)  # managed memory
    wp.launch(_scale, 16, [a], device="cuda:0")
    np.testing.assert_allclose(a.numpy(), 6.0)
    b = wp.zeros(4, dtype=float, device="cuda:0")
    assert not wp.can_access("cpu", b)
    with wp.ScopedMemoryTracker("gpu", print=False):
        c = wp.zeros(256, dtype=float, device="cuda:0")
        out = io.StringIO()
        wp.print_memory_report(out)
        assert "cuda:0" in out.getvalue()
    del c
