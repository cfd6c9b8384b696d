"""The ``interp`` backend: runs kdsl IR in Python through the op catalog.

It is the executable definition of every op (each op's ``interp`` rule), the
oracle of the conformance suite, and the worked example of a backend plugin.
It is slow: one Python call per op per thread.
"""

from __future__ import annotations

from typing import Any

from kdsl.backends.base import Args, Backend, CompiledKernel, Dims, Job
from kdsl.backends.interp.program import Program, run_kernel


class InterpBackend(Backend):
    """A reference interpreter of kdsl IR on the host."""

    name = "interp"
    version = "1"
    capabilities = frozenset(
        {"fp16", "fp32", "fp64", "int8", "int16", "int64", "atomics"}
    )

    #: Nothing to cache: the program is built from the module in Python.
    cacheable = False

    def devices(self) -> list[str]:
        return ["cpu"]

    def load(self, job: Job) -> CompiledKernel:
        program = Program(job.module)
        fn = program.function(job.symbol)  # compile the kernel now, callees on use
        return CompiledKernel(
            self.name, job.symbol, job.module, program, {"tid_ndims": sorted(fn.tid_ndims)}
        )

    def launch(self, compiled: CompiledKernel, dims: Dims, args: Args, stream: Any = None) -> None:
        run_kernel(
            compiled.payload, compiled.symbol, tuple(dims), args, compiled.metadata.get("name")
        )
