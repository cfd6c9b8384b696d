"""The ``cpu`` backend: LLVM (through llvmlite) for the host, run on a thread pool.

Registered by the entry point ``cpu = "kdsl.backends.cpu:BACKEND"``.
"""

from kdsl.backends.cpu.backend import CpuBackend
from kdsl.backends.cpu.pool import num_threads, set_num_threads

#: The instance the ``kdsl.backends`` entry point names.
BACKEND = CpuBackend()

__all__ = ["BACKEND", "CpuBackend", "num_threads", "set_num_threads"]
