"""The ``cuda`` backend: kdsl IR -> CUDA C -> NVRTC cubin, launched on CuPy streams.

CuPy (and NVRTC through it) is imported only when a kernel is compiled, lowered to
PTX or launched, so ``import kdsl`` and listing backends work without it.
"""

from __future__ import annotations

import ctypes
import functools
import os
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from kdsl.backends import checks_common
from kdsl.backends.base import (
    Args,
    Backend,
    CompiledKernel,
    Dims,
    Job,
    launch_size,
    package_sources,
    source_version,
)
from kdsl.backends.cuda import nvrtc
from kdsl.backends.cuda.devices import device_count
from kdsl.backends.cuda.geometry import Geometry, fast_geometry, linear_geometry
from kdsl.backends.cuda.names import entry_name, fast_entry_name, kernel_names, tid_ndims
from kdsl.backends.cuda.params import Packer
from kdsl.backends.cuda.variants import FastPlan, fast_plan
from kdsl.errors import KdslError
from kdsl.ir.core import Module
from kdsl.ir.ops_debug import debug_sites
from kdsl.passes import DEFAULT_PIPELINE


@functools.cache
def _code_version(version: str) -> str:
    """``version`` plus a digest of this backend's sources (``base.source_version``)."""
    here = os.path.dirname(__file__)
    shared = os.path.join(os.path.dirname(here), "checks_common.py")
    return source_version(version, [*package_sources(here), shared])


def device_arch(ordinal: int) -> str:
    """``sm_XX`` for CUDA device ``ordinal``."""
    import cupy

    return nvrtc.arch_for(int(cupy.cuda.Device(ordinal).compute_capability))


def current_arch() -> str:
    """The current CUDA device's architecture, or ``nvrtc.DEFAULT_ARCH`` without a GPU."""
    if device_count() == 0:
        return nvrtc.DEFAULT_ARCH
    import cupy

    return device_arch(cupy.cuda.runtime.getDevice())


class CudaKernel:
    """The payload of a compiled cuda kernel: cubins per arch, functions per GPU.

    Its CUDA C is generated only when a cubin has to be compiled (or ``source`` is read):
    a kernel whose cubin is in the cache is never lowered.
    """

    def __init__(self, job: Job, entry: str) -> None:
        self.job = job
        self.entry = entry
        #: device ordinal -> (cupy Module, CUfunction pointers: general, fast or 0, Functions).
        self.functions: dict[int, tuple[Any, int, int, Any]] = {}
        #: The fast entry (``variants``), or None when the kernel has only the general one.
        self.plan: FastPlan | None = None
        self.tid_ndims: set[int] = set()
        self.packer: Packer | None = None
        #: Debug builds: the check sites (``kdsl.ir.ops_debug``); None in release builds.
        self.sites: dict | None = None

    @property
    def source(self) -> str:
        """The kernel's CUDA C (generated on first use)."""
        return _source(self.job).text

    def cubin(self, arch: str) -> bytes:
        """The cubin for ``arch``, from the kernel cache or compiled now."""
        return self.job.artifact(arch)

    def function(self, ordinal: int, fast: bool = False) -> int:
        """The ``CUfunction`` of this kernel (its fast entry with ``fast``) on device
        ``ordinal``, loaded on first use."""
        hit = self.functions.get(ordinal)
        if hit is None:
            import cupy

            with cupy.cuda.Device(ordinal):
                mod = cupy.cuda.function.Module()
                mod.load(self.cubin(device_arch(ordinal)))
                fn = mod.get_function(self.entry)
                fns = [fn]
                if self.plan is not None:
                    fns.append(mod.get_function(fast_entry_name(self.job.symbol)))
                hit = self.functions[ordinal] = (mod, fn.ptr, fns[-1].ptr, fns)
        return hit[2] if fast else hit[1]

    def geometry(self, args: Args, dims: tuple[int, ...], total: int) -> tuple[bool, Geometry]:
        """(fast, (grid, block)) of a launch: the fast entry where the launch-time tests
        of ``geometry.fast_geometry`` pass, else the general one."""
        if self.plan is not None:
            fast = fast_geometry(self.plan, args, dims, total)
            if fast is not None:
                return True, fast
        return False, linear_geometry(total)


class CudaBackend(Backend):
    """Compiles kernels to CUDA C with NVRTC and launches them on CuPy streams.

    Options: ``fast_math`` (NVRTC ``--use_fast_math``), ``debug`` / ``verify_fp``
    (checked builds, see ``checks``), ``arch`` (``"sm_90"``: compile for that
    architecture instead of the current GPU's; for compile-only use).
    """

    name = "cuda"
    version = "1"
    capabilities = frozenset({"fp16", "fp32", "fp64", "int8", "int16", "int64", "atomics"})

    emit_stages = ("cuda-c", "ptx")
    #: The standard pipeline, then ``block-cache``: all-pairs loops read shared tiles.
    pipeline = f"{DEFAULT_PIPELINE},block-cache"
    target_options = ("arch",)

    def devices(self) -> list[str]:
        return [f"cuda:{i}" for i in range(device_count())]

    def code_version(self) -> str:
        return _code_version(self.version)

    def cache_target(self, target: str) -> str:
        return f"{target}/{nvrtc.cache_name()}"

    def emit(self, module: Module, stage: str, options: dict[str, Any], checked: bool) -> str:
        """The module at ``stage``. "cuda-c" needs no GPU; "ptx" needs NVRTC only."""
        from kdsl.backends.cuda.lower import generate

        src = generate(module, kernel_names(module), checked, max_registers(options)).text
        if stage == "cuda-c":
            return src
        arch = options.get("arch") or current_arch()
        return nvrtc.compile_source(src, arch, bool(options.get("fast_math")), module).ptx

    def build(self, job: Job, target: str) -> bytes:
        """The cubin of ``job`` for the architecture ``target`` ("sm_90")."""
        fast = bool(job.options.get("fast_math", False))
        gen = _source(job)
        if gen.entries[job.symbol] != entry_name(job.symbol):  # how load finds the kernel
            raise KdslError(f"cuda backend: kernel {job.symbol!r} was emitted as "
                            f"{gen.entries[job.symbol]!r}, not {entry_name(job.symbol)!r}")  # fmt: skip
        return nvrtc.compile_source(gen.text, target, fast, job.module, job.symbol).cubin

    def load(self, job: Job) -> CompiledKernel:
        module, symbol = job.module, job.symbol
        func = module.get_func(symbol)
        payload = CudaKernel(job, entry_name(symbol))
        payload.tid_ndims = tid_ndims(func)
        payload.plan = fast_plan(module, symbol, job.checked)
        args = func.regions[0].block.args
        payload.packer = Packer(
            [a.type for a in args], [a.name_hint or f"arg{i}" for i, a in enumerate(args)],
            job.checked,
        )  # fmt: skip
        if job.checked:
            payload.sites = debug_sites(module)
        arch = job.options.get("arch") or current_arch()
        payload.cubin(arch)  # compile errors surface here, not at the first launch
        meta = {"tid_ndims": sorted(payload.tid_ndims), "arch": arch}
        return CompiledKernel(self.name, symbol, module, payload, meta)

    def launch(self, compiled: CompiledKernel, dims: Dims, args: Args, stream: Any = None) -> None:
        k: CudaKernel = compiled.payload
        name = compiled.metadata.get("name") or compiled.symbol
        dims = tuple(int(d) for d in dims)
        total = launch_size(compiled, dims, k.tid_ndims, self.name)
        if total == 0:
            return
        ordinal, raw = _stream_of(stream)
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
        fast, ((gx, gy, gz), (bx, by, bz)) = k.geometry(args, dims, total)
        fn = k.function(ordinal, fast)
        _on_device(ordinal, driver.launchKernel, fn, gx, gy, gz, bx, by, bz, 0, raw,
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
        self, compiled: CompiledKernel, dims: Dims, args: Args, stream: Any = None
    ) -> Callable[[], None]:
        """A launch packed once: calling it is one ``cuLaunchKernel`` (release builds)."""
        if compiled.payload.sites is not None:  # a checked build needs a fresh error record
            return super().prepare(compiled, dims, args, stream)
        return self._prepared(compiled, dims, args, stream, list(args))[0]

    def prepare_reusable(
        self, compiled: CompiledKernel, dims: Dims, args: Args, stream: Any = None
    ) -> Callable[[], None] | None:
        """``prepare`` holding only the packed parameters (the runtime keeps buffers alive)."""
        if compiled.payload.sites is not None:
            return None
        return self._prepared(compiled, dims, args, stream, None)[0]

    def prepare_patchable(
        self, compiled: CompiledKernel, dims: Dims, args: Args, stream: Any = None,
        values: Sequence[int] = (),
    ) -> tuple[Callable[[], None], Callable[[Sequence[Any]], None]] | None:  # fmt: skip
        """``prepare_reusable`` with a ``write`` patching the by-value parameters ``values``
        in the packed buffer (``Packer.writer``): ``cuLaunchKernel`` copies the parameters
        when it is called, so a write after a run never reaches that launch."""
        k: CudaKernel = compiled.payload
        if k.sites is not None:
            return None
        into = k.packer.writer(values)
        run, buf = self._prepared(compiled, dims, args, stream, None)
        if buf is None:  # an empty grid: nothing runs, nothing to patch
            return run, _ignore
        return run, functools.partial(into, buf)

    def _prepared(
        self, compiled: CompiledKernel, dims: Dims, args: Args, stream: Any, hold: Any
    ) -> tuple[Callable[[], None], Any]:
        """The packed launch and its parameter buffer (None for an empty grid); ``hold``
        (the arguments, or None) is kept alive with it."""
        k: CudaKernel = compiled.payload
        total = launch_size(compiled, dims, k.tid_ndims, self.name)
        if total == 0:
            return _ignore, None
        ordinal, raw = _stream_of(stream)
        grid = (total, *dims, *([1] * (4 - len(dims))))
        buf, params = k.packer.pack(args, ordinal, grid)
        fast, ((gx, gy, gz), (bx, by, bz)) = k.geometry(args, tuple(int(d) for d in dims), total)
        fn = k.function(ordinal, fast)
        driver, _ = _cuda_api()
        launch_kernel, addr = driver.launchKernel, ctypes.addressof(params)

        if device_count() == 1:  # the only device is always the current one

            def run() -> None:
                launch_kernel(fn, gx, gy, gz, bx, by, bz, 0, raw, addr, 0)

        else:

            def run() -> None:
                _on_device(ordinal, launch_kernel, fn, gx, gy, gz, bx, by, bz, 0, raw, addr, 0)

        run.keep = (buf, params, hold)  # type: ignore[attr-defined]
        return run, buf


def _ignore(*_: Any) -> None:
    """A prepared launch over an empty grid, and its parameters' writer."""


def _source(job: Job) -> Any:
    """The CUDA C of ``job``'s kernel, generated once per job."""
    gen = job.notes.get("cuda-c")
    if gen is None:  # the code generator is imported here: a cache hit never needs it
        from kdsl.backends.cuda.lower import generate

        gen = generate(job.module, [job.symbol], job.checked, max_registers(job.options))
        job.notes["cuda-c"] = gen
    return gen


def max_registers(options: Mapping[str, Any]) -> int | None:
    """The kernel option ``cuda_max_registers`` (Warp's: the most registers a thread of
    the kernel may use, ``__maxnreg__``), or None; anything but a positive int is a
    ``KdslError``."""
    n = options.get("cuda_max_registers")
    if n is None:
        return None
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise KdslError(f"kernel option cuda_max_registers must be a positive int, not {n!r}")
    return n


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
    if device_count() == 1:  # the only device is always the current one: no query
        return fn(*args)
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
