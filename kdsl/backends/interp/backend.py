"""The ``interp`` backend: runs kdsl IR in Python through the op catalog.

It is the executable definition of every op (each op's ``interp`` rule), the
oracle of the conformance suite, and the worked example of a backend plugin.
It is slow: one Python call per op per thread.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from kdsl.backends.base import Backend, CompiledKernel, optimize
from kdsl.backends.interp.program import Program, run_kernel
from kdsl.config import check_pipeline
from kdsl.errors import KdslError
from kdsl.ir.core import Module
from kdsl.ir.printer import print_module


class InterpBackend(Backend):
    """A reference interpreter of kdsl IR on the host."""

    name = "interp"
    version = "1"
    capabilities = frozenset(
        {"fp16", "fp32", "fp64", "int8", "int16", "int64", "atomics", "recursion"}
    )

    def devices(self) -> list[str]:
        return ["cpu"]

    def stages(self) -> list[str]:
        return ["kir", "kir-opt"]

    def lower(self, module: Module, stage: str) -> str:
        if stage == "kir":
            return print_module(module)
        if stage == "kir-opt":
            return print_module(optimize(module, self.pipeline))
        raise KdslError(f"the interp backend has no stage {stage!r} (stages: {self.stages()})")

    def compile(
        self, module: Module, kernel_symbol: str, options: dict[str, Any] | None = None
    ) -> CompiledKernel:
        opts = dict(options or {})
        if opts.get("optimize", True):
            module = optimize(module, self.pipeline)
        module = optimize(module, check_pipeline(opts))  # debug / verify_fp checks
        program = Program(module)
        fn = program.function(kernel_symbol)  # compile the kernel now, callees on use
        return CompiledKernel(
            self.name, kernel_symbol, module, program, {"tid_ndims": sorted(fn.tid_ndims)}
        )

    def launch(
        self,
        compiled: CompiledKernel,
        dims: tuple[int, ...],
        args: Sequence[Any],
        stream: Any = None,
    ) -> None:
        run_kernel(
            compiled.payload, compiled.symbol, tuple(dims), args, compiled.metadata.get("name")
        )
