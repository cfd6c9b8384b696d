"""Public names of Warp's memory, device-query, build-option and profiler API (issue 14).

Gathered apart from ``kdsl.runtime.api`` so each subsystem lists its own names; the
facade star-imports both.
"""

from kdsl.runtime.allocators import (
    Allocator,
    CudaManagedAllocator,
    MemoryKind,
    ScopedAllocator,
    can_access,
    get_device_allocator,
    set_cuda_allocator,
    set_device_allocator,
)
from kdsl.runtime.aot import compile_aot_module, get_cpu_kernel_cache_key, load_aot_module
from kdsl.runtime.build_options import (
    DeterministicMode,
    DeviceLike,
    JaxModulePreloadMode,
    ModuleBuildOptions,
)
from kdsl.runtime.cuda_info import (
    ScopedCudaProfiler,
    clear_lto_cache,
    cuda_profiler_start,
    cuda_profiler_stop,
    get_cuda_driver_version,
    get_cuda_kernel_properties,
    get_cuda_max_cluster_dim,
    get_cuda_supported_archs,
    get_cuda_toolkit_version,
    get_suggested_block_size,
    print_diagnostics,
)
from kdsl.runtime.memory_tracker import ScopedMemoryTracker, print_memory_report
from kdsl.types import uint64

#: Warp's type of object handles (Mesh, Volume, BVH ids) in kernel parameters, struct
#: fields and arrays: Warp's behaves as ``uint64``, and in kdsl it is ``uint64``.
handle = uint64

__all__ = [
    "Allocator", "CudaManagedAllocator", "DeterministicMode", "DeviceLike",
    "JaxModulePreloadMode", "MemoryKind", "ModuleBuildOptions", "ScopedAllocator",
    "ScopedCudaProfiler", "ScopedMemoryTracker", "can_access", "clear_lto_cache",
    "compile_aot_module", "get_cpu_kernel_cache_key", "load_aot_module",
    "cuda_profiler_start", "cuda_profiler_stop", "get_cuda_driver_version",
    "get_cuda_kernel_properties", "get_cuda_max_cluster_dim", "get_cuda_supported_archs",
    "get_cuda_toolkit_version", "get_device_allocator", "get_suggested_block_size", "handle",
    "print_diagnostics", "print_memory_report", "set_cuda_allocator", "set_device_allocator",
]  # fmt: skip
