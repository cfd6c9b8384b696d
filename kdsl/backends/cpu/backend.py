"""The ``cpu`` backend: kdsl IR -> LLVM IR (llvmlite) -> host code, run on all cores."""

from __future__ import annotations

import ctypes
import itertools
import threading
from collections.abc import Sequence
from typing import Any

from kdsl.backends.base import Backend, CompiledKernel, optimize
from kdsl.backends.cpu import jit, pool
from kdsl.backends.cpu.abi import Packed
from kdsl.backends.cpu.lower import kernel_names, kernel_symbol, lower_kernels, tid_ndims
from kdsl.errors import KdslError, KdslLaunchError
from kdsl.ir.core import Module
from kdsl.ir.printer import print_module

#: The C type of every range function: (start, end, args, dims).
RANGE_FN = ctypes.CFUNCTYPE(None, ctypes.c_int64, ctypes.c_int64, ctypes.c_void_p, ctypes.c_void_p)
_serial = itertools.count()
_serial_lock = threading.Lock()

_MAX_THREADS = 2**31 - 1  # tid() is an i32


class CpuKernel:
    """The payload of a compiled cpu kernel: the native range function and its facts."""

    def __init__(self, fn: Any, arg_types: list, tid_ndims: set[int], llvm_name: str) -> None:
        self.fn = fn
        self.arg_types = arg_types
        self.tid_ndims = tid_ndims
        self.llvm_name = llvm_name


class CpuBackend(Backend):
    """Compiles kernels for the host CPU with LLVM and runs them over a thread pool.

    Array indices are not bounds-checked (release mode); run on ``interp`` to
    find out-of-range accesses.
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

    def lower(self, module: Module, stage: str) -> str:
        """The module at ``stage``; "llvm-ir" is after LLVM's -O3, "llvm-ir-unopt" before."""
        if stage not in self.stages():
            raise KdslError(f"the cpu backend has no stage {stage!r} (stages: {self.stages()})")
        if stage == "kir":
            return print_module(module)
        module = optimize(module, self.pipeline)
        if stage == "kir-opt":
            return print_module(module)
        text = str(lower_kernels(module, kernel_names(module)).llmod)
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
        with _serial_lock:
            llname = f"{kernel_symbol(kernel_symbol_)}_{next(_serial)}"
        state = lower_kernels(module, [kernel_symbol_], {kernel_symbol_: llname})
        mod = jit.parse(str(state.llmod))
        jit.optimize(mod, 3 if opts.get("optimize", True) else 0)
        addr = jit.add_module(mod, [llname])[llname]
        func = module.get_func(kernel_symbol_)
        payload = CpuKernel(
            RANGE_FN(addr), [a.type for a in func.regions[0].block.args], tid_ndims(func), llname
        )
        return CompiledKernel(
            self.name, kernel_symbol_, module, payload, {"tid_ndims": sorted(payload.tid_ndims)}
        )

    def launch(
        self,
        compiled: CompiledKernel,
        dims: tuple[int, ...],
        args: Sequence[Any],
        stream: Any = None,
    ) -> None:
        k: CpuKernel = compiled.payload
        name = compiled.metadata.get("name") or compiled.symbol
        dims = tuple(int(d) for d in dims)
        for nd in k.tid_ndims:
            if nd != 1 and nd != len(dims):
                raise KdslLaunchError(
                    f"kernel '{name}' uses a {nd}-d thread index but was launched with "
                    f"{len(dims)}-d dim={dims}"
                )
        total = 1
        for d in dims:
            total *= d
        if total > _MAX_THREADS:
            raise KdslLaunchError(
                f"kernel '{name}': {total} threads is more than the "
                f"cpu backend's limit of {_MAX_THREADS}"
            )
        if total == 0:
            return
        packed = Packed(k.arg_types, args)
        extents = (ctypes.c_int64 * len(dims))(*dims)
        argp, dimp = packed.address, ctypes.addressof(extents)
        fn = k.fn
        pool.run(lambda s, e: fn(s, e, argp, dimp), total)
