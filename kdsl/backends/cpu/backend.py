"""The ``cpu`` backend: kdsl IR -> LLVM IR (llvmlite) -> host code, run on all cores."""

from __future__ import annotations

import ctypes
import functools
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from kdsl.backends.base import (
    Backend,
    CompiledKernel,
    launch_size,
    optimize,
    source_version,
)
from kdsl.backends.cpu import checks, jit, pool, printing
from kdsl.backends.cpu.abi import ArgPacker, Packed
from kdsl.backends.cpu.lower import kernel_names, kernel_symbol, lower_kernels, tid_ndims
from kdsl.config import check_pipeline
from kdsl.errors import KdslError
from kdsl.ir.core import Module
from kdsl.ir.ops_debug import debug_sites
from kdsl.ir.printer import print_module
from kdsl.runtime import cache as kernel_cache

#: The C type of every range function: (start, end, args, dims).
RANGE_FN = ctypes.CFUNCTYPE(None, ctypes.c_int64, ctypes.c_int64, ctypes.c_void_p, ctypes.c_void_p)



@functools.cache
def _code_version(version: str) -> str:
    """``version`` plus a digest of this backend's sources (``base.source_version``)."""
    return source_version(version, Path(__file__).parent.glob("*.py"))


class CpuKernel:
    """The payload of a compiled cpu kernel: the native range function and its facts."""

    def __init__(self, fn: Any, arg_types: list, tid_ndims: set[int], llvm_name: str) -> None:
        self.fn = fn
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
    version = f"1-{jit.version_tag()}"
    capabilities = frozenset(
        {"fp16", "fp32", "fp64", "int8", "int16", "int64", "atomics", "recursion"}
    )

    def devices(self) -> list[str]:
        return ["cpu"]

    def stages(self) -> list[str]:
        return ["kir", "kir-opt", "llvm-ir-unopt", "llvm-ir", "asm"]

    def lower(self, module: Module, stage: str, options: dict[str, Any] | None = None) -> str:
        """The module at ``stage``; "llvm-ir" is after LLVM's -O3, "llvm-ir-unopt" before.

        ``options`` are kernel options as ``compile`` takes them; ``fast_math`` changes
        the LLVM stages.
        """
        if stage not in self.stages():
            raise KdslError(f"the cpu backend has no stage {stage!r} (stages: {self.stages()})")
        if stage == "kir":
            return print_module(module)
        module = optimize(module, self.pipeline)
        if stage == "kir-opt":
            return print_module(module)
        fast = bool((options or {}).get("fast_math", False))
        text = str(lower_kernels(module, kernel_names(module), fast_math=fast).llmod)
        if stage == "llvm-ir-unopt":
            return text
        mod = jit.optimize(jit.parse(text))
        return str(mod) if stage == "llvm-ir" else jit.assembly(mod)

    def compile(
        self, module: Module, kernel_symbol_: str, options: dict[str, Any] | None = None
    ) -> CompiledKernel:
        opts = dict(options or {})
        if opts.get("optimize", True):
            module = optimize(module, self.pipeline)
        checked = check_pipeline(opts)
        module = optimize(module, checked)
        # The LLVM name derives from the cache key: equal keys are equal code, and the
        # kernel cache loads each key once per process, so names never clash.
        key = kernel_cache.kernel_key(
            print_module(module, debuginfo=True), self.name, _code_version(self.version),
            {**opts, "kernel": kernel_symbol_}, jit.target_id(),
        )  # fmt: skip
        llname = f"{kernel_symbol(kernel_symbol_)}_{key[:24]}"

        def build() -> bytes:
            state = lower_kernels(
                module, [kernel_symbol_], {kernel_symbol_: llname}, debug=bool(checked),
                fast_math=bool(opts.get("fast_math", False)),
            )  # fmt: skip
            mod = jit.parse(str(state.llmod))
            jit.optimize(mod, 3 if opts.get("optimize", True) else 0)
            return jit.emit_object(mod)

        addr = kernel_cache.get_or_build(
            key, build, lambda obj: jit.add_object(obj, [llname])[llname]
        )
        func = module.get_func(kernel_symbol_)
        fn = RANGE_FN(addr)
        if printing.uses_print(module):  # keep C's and Python's stdout in order
            fn = printing.flushing(fn)
        payload = CpuKernel(fn, [a.type for a in func.regions[0].block.args], tid_ndims(func), llname)
        if checked:
            payload.sites = debug_sites(module)
        meta = {"tid_ndims": sorted(payload.tid_ndims), "cache_key": key}
        return CompiledKernel(self.name, kernel_symbol_, module, payload, meta)

    def launch(
        self,
        compiled: CompiledKernel,
        dims: tuple[int, ...],
        args: Sequence[Any],
        stream: Any = None,
    ) -> None:
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
        pool.run_range(k.fn, total, argp, ctypes.addressof(extents), cost=k.cost)

    def prepare(
        self,
        compiled: CompiledKernel,
        dims: tuple[int, ...],
        args: Sequence[Any],
        stream: Any = None,
    ) -> Callable[[], None]:
        """A launch with its arguments packed once: calling it only enters native code."""
        k: CpuKernel = compiled.payload
        total = self._check_dims(compiled, dims)
        if total == 0:
            return _nothing
        if k.sites is not None:
            args = list(args)
            return lambda: self._launch_checked(compiled, dims, args, total)
        if k.packer.supported:
            buf = k.packer.new_buffer()
            argp = k.packer.pack_into(buf, args)
            keep: Any = (buf, list(args))  # the buffers the descriptors point into
        else:
            keep = Packed(k.arg_types, args)
            argp = keep.address
        extents = (ctypes.c_int64 * len(dims))(*dims)
        dimp = ctypes.addressof(extents)
        fn, run_range, cost = k.fn, pool.run_range, k.cost

        def run() -> None:
            run_range(fn, total, argp, dimp, cost=cost)

        run.keep = (keep, extents)  # type: ignore[attr-defined]
        return run

    def _check_dims(self, compiled: CompiledKernel, dims: tuple[int, ...]) -> int:
        """The number of threads of ``dims``, checked against the kernel's tid()."""
        return launch_size(compiled, dims, compiled.payload.tid_ndims, self.name)

    def _launch_checked(
        self, compiled: CompiledKernel, dims: tuple[int, ...], args: Sequence[Any], total: int
    ) -> None:
        """A debug build's launch: a fresh error record, raised from after the run."""
        k: CpuKernel = compiled.payload
        record = checks.new_record()
        packed = Packed(k.arg_types, args, (record.ctypes.data,))
        extents = (ctypes.c_int64 * len(dims))(*dims)
        pool.run_range(k.fn, total, packed.address, ctypes.addressof(extents))
        name = compiled.metadata.get("name") or compiled.symbol
        checks.raise_for_record(record, k.sites, name, compiled.symbol, dims)


def _nothing() -> None:
    """The prepared form of a launch over zero threads."""
