"""CUDA driver, toolkit and kernel queries, the CUDA profiler range, diagnostics.

All of it goes through CuPy (imported only when a CUDA device exists): the driver
version from the driver, the toolkit version and supported architectures from
NVRTC (the compiler kdsl's cuda backend uses), kernel properties and occupancy from
the driver's function attributes of the loaded kernel. Without a CUDA device the
version queries return None (or []) and the kernel queries raise, as in Warp. The
profiler calls are no-ops on the cpu.
"""

from __future__ import annotations

import platform
import sys
from typing import Any

from kdsl.config import package_version
from kdsl.errors import KdslError, KdslTypeError, KdslValueError
from kdsl.runtime.device import Device, cupy, get_device, get_devices, is_cuda_available


def _version(v: int) -> tuple[int, int]:
    return v // 1000, (v % 1000) // 10


def get_cuda_driver_version() -> tuple[int, int] | None:
    """The CUDA driver's version (major, minor), or None without CUDA."""
    if not is_cuda_available():
        return None
    return _version(int(cupy().cuda.runtime.driverGetVersion()))


def get_cuda_toolkit_version() -> tuple[int, int] | None:
    """The version (major, minor) of NVRTC, the CUDA compiler kdsl uses; None without CUDA."""
    if not is_cuda_available():
        return None
    from cupy.cuda import nvrtc

    return tuple(int(x) for x in nvrtc.getVersion())[:2]  # type: ignore[return-value]


def get_cuda_supported_archs() -> list[int]:
    """The GPU architectures NVRTC can compile for (75, 80, 86, 90, ...); [] without CUDA."""
    if not is_cuda_available():
        return []
    from cupy.cuda import nvrtc

    return sorted(int(a) for a in nvrtc.getSupportedArchs())


def _function(kernel: Any, device: Any, what: str) -> tuple[Device, Any]:
    from kdsl.runtime.launch import launch_plan

    if not hasattr(kernel, "build_module") or not hasattr(kernel, "arg_types"):
        raise KdslTypeError(f"{what} takes a @kdsl.kernel, not {type(kernel).__name__}")
    if getattr(kernel, "is_generic", False):
        raise KdslError(f"{what}: kernel '{kernel.name}' is generic; pass an instance "
                        f"(kdsl.overload(kernel, ...))")  # fmt: skip
    dev = get_device(device)
    if not dev.is_cuda:
        raise KdslError(f"{what}: '{dev}' is not a CUDA device")
    payload = launch_plan(kernel, dev, None).compiled.payload
    return dev, payload.function(dev.ordinal)


def _attribute(fn_ptr: int, name: str) -> int:
    from cupy.cuda import driver

    return int(driver.funcGetAttribute(getattr(driver, "CU_FUNC_ATTRIBUTE_" + name), fn_ptr))


def _check_block_dim(block_dim: int | None) -> None:
    if block_dim is not None and (not isinstance(block_dim, int) or block_dim <= 0):
        raise KdslValueError(f"block_dim must be a positive int, not {block_dim!r}")


def get_cuda_kernel_properties(
    kernel: Any, device: Any = None, block_dim: int | None = None
) -> dict[str, int]:
    """The compiled kernel's ``register_count`` (per thread) and ``local_memory_size``
    (bytes per thread), plus ``shared_memory_size``, ``const_memory_size`` and
    ``max_threads_per_block``. kdsl builds one binary for every block size, so
    ``block_dim`` is checked and does not change the answer."""
    _check_block_dim(block_dim)
    _, fn = _function(kernel, device, "get_cuda_kernel_properties")
    return {
        "register_count": _attribute(fn, "NUM_REGS"),
        "local_memory_size": _attribute(fn, "LOCAL_SIZE_BYTES"),
        "shared_memory_size": _attribute(fn, "SHARED_SIZE_BYTES"),
        "const_memory_size": _attribute(fn, "CONST_SIZE_BYTES"),
        "max_threads_per_block": _attribute(fn, "MAX_THREADS_PER_BLOCK"),
    }


def get_suggested_block_size(kernel: Any, device: Any = None) -> tuple[int, int]:
    """(block size, minimum grid size) maximizing occupancy, from the driver's occupancy
    calculator (``cuOccupancyMaxPotentialBlockSize``)."""
    from cupy.cuda import driver

    dev, fn = _function(kernel, device, "get_suggested_block_size")
    with cupy().cuda.Device(dev.ordinal):
        min_grid, block = driver.occupancyMaxPotentialBlockSize(fn, 0, 0)
    return int(block), int(min_grid)


def get_cuda_max_cluster_dim(
    kernel: Any, device: Any = None, *, block_dim: int | None = None, dynamic_smem_bytes: int = 0
) -> int:
    """The largest thread-block cluster the kernel can launch with: 1 below compute
    capability 9.0 (no clusters), else 8, the portable cluster size (CuPy exposes no
    ``cuOccupancyMaxPotentialClusterSize``; kdsl launches no clusters itself)."""
    _check_block_dim(block_dim)
    if not isinstance(dynamic_smem_bytes, int) or dynamic_smem_bytes < 0:
        raise KdslValueError(f"dynamic_smem_bytes must be a non-negative int, "
                             f"not {dynamic_smem_bytes!r}")  # fmt: skip
    dev, _ = _function(kernel, device, "get_cuda_max_cluster_dim")
    major, _minor = dev.arch // 10, dev.arch % 10
    return 8 if major >= 9 else 1


def cuda_profiler_start(device: Any = None) -> None:
    """Start the CUDA profiler's capture range (``cudaProfilerStart``); a no-op on the cpu."""
    dev = get_device(device)
    if dev.is_cuda:
        with cupy().cuda.Device(dev.ordinal):
            cupy().cuda.runtime.profilerStart()


def cuda_profiler_stop(device: Any = None) -> None:
    """Stop the CUDA profiler's capture range (``cudaProfilerStop``); a no-op on the cpu."""
    dev = get_device(device)
    if dev.is_cuda:
        with cupy().cuda.Device(dev.ordinal):
            cupy().cuda.runtime.profilerStop()


class ScopedCudaProfiler:
    """``with ScopedCudaProfiler(device):`` a profiler capture range (Nsight Systems'
    ``--capture-range=cudaProfilerApi``) around the block; a no-op on the cpu."""

    def __init__(self, device: Any = None) -> None:
        self.device = get_device(device)

    def __enter__(self) -> ScopedCudaProfiler:
        cuda_profiler_start(self.device)
        return self

    def __exit__(self, *exc_info: object) -> None:
        cuda_profiler_stop(self.device)


def clear_lto_cache() -> None:
    """Warp's cache of link-time-optimized MathDx objects; kdsl links no LTO objects
    (its cuda backend compiles one translation unit per module), so there is nothing
    to clear."""


def print_diagnostics() -> dict:
    """Print and return what kdsl sees: versions, backends, devices, CUDA."""
    import llvmlite
    import numpy

    info: dict[str, Any] = {
        "kdsl_version": package_version(),
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "numpy": numpy.__version__,
        "llvmlite": llvmlite.__version__,
        "cuda_available": is_cuda_available(),
        "cuda_driver_version": get_cuda_driver_version(),
        "cuda_toolkit_version": get_cuda_toolkit_version(),
        "cuda_supported_archs": get_cuda_supported_archs(),
        "devices": [str(d) for d in get_devices()],
    }
    if info["cuda_available"]:
        info["cupy"] = cupy().__version__
    width = max(len(k) for k in info)
    for k, v in info.items():
        print(f"{k:<{width}}  {v}")
    return info
