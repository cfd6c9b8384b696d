"""The ``cpu`` backend: kdsl IR -> LLVM IR (llvmlite) -> host code, run on all cores."""

from __future__ import annotations

import ctypes
import functools
import os
from collections.abc import Callable, Sequence
from typing import Any

import llvmlite  # the package only (its version); the binding is imported on a miss

from kdsl.backends import checks_common
from kdsl.backends.base import (
    Args,
    Backend,
    CompiledKernel,
    Dims,
    Job,
    SupportCode,
    launch_size,
    package_sources,
    source_version,
)
from kdsl.backends.cpu import host, native_pool, pool, print_order, shared_object
from kdsl.backends.cpu.abi import ArgPacker, Packed
from kdsl.backends.cpu.kernel_facts import kernel_names, kernel_symbol, tid_ndims, uses_print
from kdsl.ir.core import Module
from kdsl.ir.ops_debug import debug_sites

#: The C type of every range function: (start: i64, end: i64, args, dims). ``start`` and
#: ``end`` are declared pointer-sized (``c_void_p``) here: on every 64-bit ABI LLVM
#: targets an i64 and a pointer travel in the same integer register, and ctypes converts
#: a Python int to ``c_void_p`` in half the time it takes for ``c_int64`` (0.28 against
#: 0.57 us for the call, measured on the 2-core EPYC host). Both are never negative.
_INDEX = ctypes.c_void_p if ctypes.sizeof(ctypes.c_void_p) == 8 else ctypes.c_int64
RANGE_FN = ctypes.CFUNCTYPE(None, _INDEX, _INDEX, ctypes.c_void_p, ctypes.c_void_p)


@functools.cache
def _code_version(version: str) -> str:
    """``version`` plus a digest of this backend's sources (``base.source_version``)."""
    return source_version(version, package_sources(os.path.dirname(__file__)))


def _llvm_name(job: Job, target: str) -> str:
    """The kernel's LLVM symbol. It derives from the cache key: equal keys are equal code,
    and the kernel cache loads each key once per process, so names never clash."""
    return f"{kernel_symbol(job.symbol)}_{job.key(target)[:24]}"


class CpuKernel:
    """The payload of a compiled cpu kernel: the native range function and its facts."""

    def __init__(
        self, fn: Any, arg_types: list, tid_ndims: set[int], llvm_name: str, address: int | None
    ) -> None:
        self.fn = fn
        #: The range function's native address, for the native pool (None: the Python
        #: pool runs it, e.g. a kernel that prints and must flush around its run).
        self.address = address
        self.arg_types = arg_types
        self.tid_ndims = tid_ndims
        self.llvm_name = llvm_name
        #: Debug builds: the check sites (``kdsl.ir.ops_debug``); None in release builds.
        self.sites: dict | None = None
        self.packer = ArgPacker(arg_types)
        #: The measured cost per thread, which decides inline versus pool (``pool``).
        self.cost = pool.RangeCost()


class CpuBackend(Backend):
    """Compiles kernels for the host CPU with LLVM and runs them over a thread pool.

    Array indices are not bounds-checked in release mode. With the ``debug`` (or
    ``verify_fp``) option the module goes through ``bounds-check`` (``fp-check``)
    after optimization and the launch reports the first failed check (``checks``).
    """

    name = "cpu"
    #: The LLVM build is part of the target (``host.target_id``), so the cache key has it.
    version = f"2-llvmlite-{llvmlite.__version__}"
    capabilities = frozenset({"fp16", "fp32", "fp64", "int8", "int16", "int64", "atomics"})

    emit_stages = ("llvm-ir-unopt", "llvm-ir", "asm")

    def devices(self) -> list[str]:
        return ["cpu"]

    def code_version(self) -> str:
        return _code_version(self.version)

    def emit(self, module: Module, stage: str, options: dict[str, Any], checked: bool) -> str:
        """The module at ``stage``; "llvm-ir" is after LLVM's -O3, "llvm-ir-unopt" before.

        ``fast_math`` changes the LLVM stages.
        """
        from kdsl.backends.cpu import jit
        from kdsl.backends.cpu.lower import lower_kernels

        fast = bool(options.get("fast_math", False))
        text = str(lower_kernels(module, kernel_names(module), fast_math=fast).llmod)
        if stage == "llvm-ir-unopt":
            return text
        mod = jit.optimize(jit.parse(text))
        return str(mod) if stage == "llvm-ir" else jit.assembly(mod)

    def build(self, job: Job, target: str) -> bytes:
        """The kernel for the host (the only target) at -O3 (-O0 with ``optimize=False``):
        a shared object where a linker is found (``shared_object``), else object code."""
        from kdsl.backends.cpu.lower import lower_kernels

        opts = job.options
        state = lower_kernels(
            job.module, [job.symbol], {job.symbol: _llvm_name(job, target)}, debug=job.checked,
            fast_math=bool(opts.get("fast_math", False)),
        )  # fmt: skip
        return _binary(str(state.llmod), 3 if opts.get("optimize", True) else 0)

    def load_artifact(self, job: Job, target: str, data: bytes) -> int:
        """The address of the kernel's range function (see ``_load_binary``)."""
        name = _llvm_name(job, target)
        return _load_binary(data, [name])[name]

    def support(self) -> list[SupportCode]:
        """The native thread pool's runtime (``native_pool``), where this host has one and
        ``KDSL_CPU_POOL`` is not ``python``."""
        text = native_pool.source()
        if text is None or os.environ.get("KDSL_CPU_POOL", "").strip().lower() == "python":
            return []
        names = native_pool.symbols(text)

        def load(data: bytes) -> dict[str, int]:
            found = _load_binary(data, list(names.values()))
            addresses = {role: found[symbol] for role, symbol in names.items()}
            pool.install_native(native_pool.NativePool(addresses))
            return addresses

        return [SupportCode("native-pool", text, host.target_id(), lambda: _binary(text), load)]

    def load(self, job: Job) -> CompiledKernel:
        target = host.target_id()
        address = job.artifact(target)
        fn = RANGE_FN(address)
        module, symbol = job.module, job.symbol
        if uses_print(module):  # keep C's and Python's stdout in order
            fn, address = print_order.flushing(fn), None
        func = module.get_func(symbol)
        payload = CpuKernel(fn, [a.type for a in func.regions[0].block.args], tid_ndims(func),
                            _llvm_name(job, target), address)  # fmt: skip
        if job.checked:
            payload.sites = debug_sites(module)
        meta = {"tid_ndims": sorted(payload.tid_ndims), "cache_key": job.key(target)}
        return CompiledKernel(self.name, symbol, module, payload, meta)

    def launch(self, compiled: CompiledKernel, dims: Dims, args: Args, stream: Any = None) -> None:
        k: CpuKernel = compiled.payload
        total = self._check_dims(compiled, dims)
        if total == 0:
            return
        if k.sites is not None:
            self._launch_checked(compiled, dims, args, total)
            return
        packer = k.packer
        if packer.supported:
            argp = packer.pack_into(packer.thread_buffer(), args)
            keep = None
        else:
            keep = Packed(k.arg_types, args)
            argp = keep.address
        extents = (ctypes.c_int64 * len(dims))(*dims)
        pool.run_range(k.fn, total, argp, ctypes.addressof(extents), cost=k.cost,
                       address=k.address)  # fmt: skip

    def prepare(
        self, compiled: CompiledKernel, dims: Dims, args: Args, stream: Any = None
    ) -> Callable[[], None]:
        """A launch with its arguments packed once: calling it only enters native code."""
        return self._prepared(compiled, dims, args, hold=True)[0]

    def prepare_reusable(
        self, compiled: CompiledKernel, dims: Dims, args: Args, stream: Any = None
    ) -> Callable[[], None] | None:
        """``prepare`` holding only the packed bytes (the runtime keeps the buffers alive).

        None for a debug build, which packs a fresh error record every launch.
        """
        if compiled.payload.sites is not None:
            return None
        return self._prepared(compiled, dims, args, hold=False)[0]

    def prepare_patchable(
        self, compiled: CompiledKernel, dims: Dims, args: Args, stream: Any = None,
        values: Sequence[int] = (),
    ) -> tuple[Callable[[], None], Callable[[Sequence[Any]], None]] | None:  # fmt: skip
        """``prepare_reusable`` with a ``write`` patching the by-value parameters ``values``
        in the packed bytes (``ArgPacker.writer``): a run returns when every thread of the
        launch is done, so a write never reaches a running launch. None for a debug build
        or a signature ``ArgPacker`` cannot pack."""
        k: CpuKernel = compiled.payload
        if k.sites is not None or not k.packer.supported:
            return None
        into = k.packer.writer(values)
        run, buf = self._prepared(compiled, dims, args, hold=False)
        if buf is None:  # an empty grid: nothing runs, nothing to patch
            return run, _nothing
        return run, functools.partial(into, buf)

    def _prepared(
        self, compiled: CompiledKernel, dims: Dims, args: Args, hold: bool
    ) -> tuple[Callable[[], None], Any]:
        """The packed launch and its argument buffer (None when there is none to patch:
        an empty grid, a debug build, a signature ``Packed`` packs); ``hold`` keeps the
        argument buffers alive with it."""
        k: CpuKernel = compiled.payload
        total = self._check_dims(compiled, dims)
        if total == 0:
            return _nothing, None
        if k.sites is not None:
            args = list(args)
            return lambda: self._launch_checked(compiled, dims, args, total), None
        buf = None
        if k.packer.supported:
            buf = k.packer.new_buffer()
            argp = k.packer.pack_into(buf, args)
            keep: Any = (buf, list(args) if hold else None)
        else:  # Packed copies descriptors and values: it holds no argument buffer
            keep = Packed(k.arg_types, args)
            argp = keep.address
        extents = (ctypes.c_int64 * len(dims))(*dims)
        dimp = ctypes.addressof(extents)
        fn, run_range, cost, address = k.fn, pool.run_range, k.cost, k.address
        native, record, whole = pool.native(), None, None
        if native is not None and address is not None:  # one ctypes argument, not four
            record = native_pool.record(address, total, argp, dimp)
            whole = functools.partial(native.call, ctypes.addressof(record))

        def run() -> None:
            run_range(fn, total, argp, dimp, cost=cost, address=address, whole=whole)

        run.keep = (keep, extents, record)  # type: ignore[attr-defined]
        return run, buf

    def _check_dims(self, compiled: CompiledKernel, dims: Dims) -> int:
        """The number of threads of ``dims``, checked against the kernel's tid()."""
        return launch_size(compiled, dims, compiled.payload.tid_ndims, self.name)

    def _launch_checked(self, compiled: CompiledKernel, dims: Dims, args: Args, total: int) -> None:
        """A debug build's launch: a fresh error record, raised from after the run."""
        k: CpuKernel = compiled.payload
        record = checks_common.new_record()
        packed = Packed(k.arg_types, args, (record.ctypes.data,))
        extents = (ctypes.c_int64 * len(dims))(*dims)
        pool.run_range(k.fn, total, packed.address, ctypes.addressof(extents),
                       address=k.address)  # fmt: skip
        name = compiled.metadata.get("name") or compiled.symbol
        checks_common.raise_for_record(record, k.sites, name, compiled.symbol, dims)


def _binary(llvm_ir: str, level: int = 3) -> bytes:
    """LLVM IR text at -O``level`` as a shared object where a linker is found
    (``shared_object``), else as object code for llvmlite's JIT."""
    from kdsl.backends.cpu import jit

    mod = jit.parse(llvm_ir)
    jit.optimize(mod, level)
    if shared_object.linker() is not None:
        linked = shared_object.link(jit.emit_object(mod, shared=True))
        if linked is not None:
            return linked
    return jit.emit_object(mod)


def _load_binary(data: bytes, symbols: list[str]) -> dict[str, int]:
    """The addresses of ``symbols`` in ``data``: a shared object is loaded with ``ctypes``
    (no llvmlite), object code is added to llvmlite's JIT."""
    if shared_object.is_shared_object(data):
        return shared_object.load(data, symbols)
    from kdsl.backends.cpu import jit

    return jit.add_object(data, symbols)


def _nothing(*_: Any) -> None:
    """The prepared form of a launch over zero threads (and its parameters' writer)."""
