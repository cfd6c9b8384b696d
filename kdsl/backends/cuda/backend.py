"""The ``cuda`` backend: kdsl IR -> CUDA C -> NVRTC cubin, launched on CuPy streams.

CuPy (and NVRTC through it) is imported only when a kernel is compiled, lowered to
PTX or launched, so ``import kdsl`` and listing backends work without it.
"""

from __future__ import annotations

import ctypes
import functools
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from kdsl.backends import checks_common
from kdsl.backends.base import (
    Backend,
    CompiledKernel,
    launch_size,
    optimize,
    source_version,
)
from kdsl.backends.cuda import nvrtc
from kdsl.backends.cuda.lower import BLOCK, generate, kernel_names, tid_ndims
from kdsl.backends.cuda.params import Packer
from kdsl.config import check_pipeline
from kdsl.errors import KdslError
from kdsl.ir.core import Module
from kdsl.ir.ops_debug import debug_sites
from kdsl.ir.printer import print_module
from kdsl.runtime import cache as kernel_cache


@functools.cache
def _code_version(version: str) -> str:
    """``version`` plus a digest of this backend's sources (``base.source_version``)."""
    here = Path(__file__).parent
    return source_version(version, [*here.glob("*.py"), here.parent / "checks_common.py"])


def device_arch(ordinal: int) -> str:
    """``sm_XX`` for CUDA device ``ordinal``."""
    import cupy

    return nvrtc.arch_for(int(cupy.cuda.Device(ordinal).compute_capability))


def current_arch() -> str:
    """The current CUDA device's architecture, or ``nvrtc.DEFAULT_ARCH`` without a GPU."""
    from kdsl.runtime.device import cuda_device_count

    if cuda_device_count() == 0:
        return nvrtc.DEFAULT_ARCH
    import cupy

    return device_arch(cupy.cuda.runtime.getDevice())


class CudaKernel:
    """The payload of a compiled cuda kernel: source, cubins per arch, functions per GPU."""

    def __init__(self, source: str, entry: str, ir_text: str, options: dict, symbol: str) -> None:
        self.source = source
        self.entry = entry
        self.ir_text = ir_text
        self.options = options
        self.symbol = symbol
        self.module: Module | None = None
        self.cubins: dict[str, bytes] = {}
        #: device ordinal -> (cupy Module, CUfunction pointer, Function); kept so it stays loaded.
        self.functions: dict[int, tuple[Any, int, Any]] = {}
        self.tid_ndims: set[int] = set()
        self.packer: Packer | None = None
        #: Debug builds: the check sites (``kdsl.ir.ops_debug``); None in release builds.
        self.sites: dict | None = None

    def cache_key(self, arch: str) -> str:
        return kernel_cache.kernel_key(
            self.ir_text, "cuda", _code_version(CudaBackend.version),
            {**self.options, "kernel": self.symbol}, f"{arch}/nvrtc-{nvrtc.version()}",
        )  # fmt: skip

    def cubin(self, arch: str) -> bytes:
        """The cubin for ``arch``, from the kernel cache or compiled now."""
        out = self.cubins.get(arch)
        if out is None:
            fast = bool(self.options.get("fast_math", False))

            def build() -> bytes:
                return nvrtc.compile_source(self.source, arch, fast, self.module, self.symbol).cubin

            out = self.cubins[arch] = kernel_cache.get_or_build(self.cache_key(arch), build, bytes)
        return out

    def function(self, ordinal: int) -> int:
        """The ``CUfunction`` of this kernel on device ``ordinal``, loaded on first use."""
        hit = self.functions.get(ordinal)
        if hit is None:
            import cupy

            with cupy.cuda.Device(ordinal):
                mod = cupy.cuda.function.Module()
                mod.load(self.cubin(device_arch(ordinal)))
                fn = mod.get_function(self.entry)
                hit = self.functions[ordinal] = (mod, fn.ptr, fn)
        return hit[1]


class CudaBackend(Backend):
    """Compiles kernels to CUDA C with NVRTC and launches them on CuPy streams.

    Options: ``fast_math`` (NVRTC ``--use_fast_math``), ``debug`` / ``verify_fp``
    (checked builds, see ``checks``), ``arch`` (``"sm_90"``: compile for that
    architecture instead of the current GPU's; for compile-only use).
    """

    name = "cuda"
    version = "1"
    capabilities = frozenset({"fp16", "fp32", "fp64", "int8", "int16", "int64", "atomics"})

    def devices(self) -> list[str]:
        from kdsl.runtime.device import cuda_device_count

        return [f"cuda:{i}" for i in range(cuda_device_count())]

    def stages(self) -> list[str]:
        return ["kir", "kir-opt", "cuda-c", "ptx"]

    def lower(self, module: Module, stage: str, options: dict[str, Any] | None = None) -> str:
        """The module at ``stage``. "cuda-c" needs no GPU; "ptx" needs NVRTC only."""
        if stage not in self.stages():
            raise KdslError(f"the cuda backend has no stage {stage!r} (stages: {self.stages()})")
        if stage == "kir":
            return print_module(module)
        opts = dict(options or {})
        module = optimize(module, self.pipeline)
        checked = check_pipeline(opts)
        module = optimize(module, checked)
        if stage == "kir-opt":
            return print_module(module)
        src = generate(module, kernel_names(module), debug=bool(checked)).text
        if stage == "cuda-c":
            return src
        arch = opts.get("arch") or current_arch()
        return nvrtc.compile_source(src, arch, bool(opts.get("fast_math")), module).ptx

    def compile(
        self, module: Module, kernel_symbol: str, options: dict[str, Any] | None = None
    ) -> CompiledKernel:
        opts = dict(options or {})
        if opts.get("optimize", True):
            module = optimize(module, self.pipeline)
        checked = check_pipeline(opts)
        module = optimize(module, checked)
        gen = generate(module, [kernel_symbol], debug=bool(checked))
        func = module.get_func(kernel_symbol)
        payload = CudaKernel(
            gen.text, gen.entries[kernel_symbol], print_module(module, debuginfo=True),
            {k: v for k, v in opts.items() if k != "arch"}, kernel_symbol,
        )  # fmt: skip
        payload.module = module
        payload.tid_ndims = tid_ndims(func)
        args = func.regions[0].block.args
        payload.packer = Packer(
            [a.type for a in args], [a.name_hint or f"arg{i}" for i, a in enumerate(args)],
            bool(checked),
        )  # fmt: skip
        if checked:
            payload.sites = debug_sites(module)
        arch = opts.get("arch") or current_arch()
        payload.cubin(arch)  # compile errors surface here, not at the first launch
        meta = {"tid_ndims": sorted(payload.tid_ndims), "arch": arch, "source": gen.text}
        return CompiledKernel(self.name, kernel_symbol, module, payload, meta)

    def launch(
        self,
        compiled: CompiledKernel,
        dims: tuple[int, ...],
        args: Sequence[Any],
        stream: Any = None,
    ) -> None:
        k: CudaKernel = compiled.payload
        name = compiled.metadata.get("name") or compiled.symbol
        dims = tuple(int(d) for d in dims)
        total = launch_size(compiled, dims, k.tid_ndims, self.name)
        if total == 0:
            return
        ordinal, raw = _stream_of(stream)
        fn = k.function(ordinal)
        grid = (total, *dims, *([1] * (4 - len(dims))))
        driver, runtime = _cuda_api()

        record = None
        if k.sites is not None:
            import cupy

            with cupy.cuda.Device(ordinal):
                record = cupy.empty(checks_common.RECORD_LEN, dtype=cupy.int64)
            runtime.memsetAsync(record.data.ptr, 0, record.nbytes, raw)
        buf, params = k.packer.pack(
            args, ordinal, grid, None if record is None else record.data.ptr
        )
        blocks = (total + BLOCK - 1) // BLOCK
        _on_device(ordinal, driver.launchKernel, fn, blocks, 1, 1, BLOCK, 1, 1, 0, raw,
                   ctypes.addressof(params), 0)  # fmt: skip
        del buf
        if record is not None:
            host = checks_common.new_record()
            runtime.memcpyAsync(
                host.ctypes.data, record.data.ptr, record.nbytes, runtime.memcpyDeviceToHost, raw
            )
            runtime.streamSynchronize(raw)
            checks_common.raise_for_record(host, k.sites, name, compiled.symbol, dims)

    def prepare(
        self,
        compiled: CompiledKernel,
        dims: tuple[int, ...],
        args: Sequence[Any],
        stream: Any = None,
    ) -> Callable[[], None]:
        """A launch packed once: calling it is one ``cuLaunchKernel`` (release builds)."""
        k: CudaKernel = compiled.payload
        if k.sites is not None:  # a checked build needs a fresh error record each time
            return super().prepare(compiled, dims, args, stream)
        args = list(args)
        total = launch_size(compiled, dims, k.tid_ndims, self.name)
        if total == 0:
            return lambda: None
        ordinal, raw = _stream_of(stream)
        fn = k.function(ordinal)
        grid = (total, *dims, *([1] * (4 - len(dims))))
        buf, params = k.packer.pack(args, ordinal, grid)
        blocks = (total + BLOCK - 1) // BLOCK
        driver, _ = _cuda_api()
        launch_kernel, addr = driver.launchKernel, ctypes.addressof(params)

        def run() -> None:
            _on_device(ordinal, launch_kernel, fn, blocks, 1, 1, BLOCK, 1, 1, 0, raw, addr, 0)

        run.keep = (buf, params, args)  # type: ignore[attr-defined]
        return run


_API: tuple[Any, Any] | None = None


def _cuda_api() -> tuple[Any, Any]:
    """CuPy's driver and runtime bindings, imported on first use (not at ``import kdsl``)."""
    global _API
    if _API is None:
        from cupy_backends.cuda.api import driver, runtime

        _API = (driver, runtime)
    return _API


def _on_device(ordinal: int, fn: Callable[..., Any], *args: Any) -> Any:
    """``fn(*args)`` with CUDA device ``ordinal`` current (switching only when needed)."""
    runtime = _cuda_api()[1]
    current = runtime.getDevice()
    if current == ordinal:
        return fn(*args)
    runtime.setDevice(ordinal)
    try:
        return fn(*args)
    finally:
        runtime.setDevice(current)


def _stream_of(stream: Any) -> tuple[int, int]:
    """(device ordinal, raw ``cudaStream_t``) of a kdsl ``Stream`` (or the current ones)."""
    if stream is not None:
        return int(stream.device.ordinal), int(stream.cuda_stream)
    import cupy

    return int(cupy.cuda.runtime.getDevice()), int(cupy.cuda.get_current_stream().ptr)
