"""The ``cuda`` backend: kdsl IR -> CUDA C (only what a module uses) -> NVRTC -> CuPy launch.

Registered by the entry point ``cuda = "kdsl.backends.cuda:BACKEND"``.

Choices (see docs/backends.md, section "cuda"):

- Indexing: one compiled variant per kernel. The thread's linear index is 32-bit
  (``tid()`` is an int32, so a launch has at most 2**31 - 1 threads, as on cpu);
  an exact grid of 256-thread blocks, each thread runs one index (no grid-stride
  loop); an n-d ``tid()`` is split from the linear index row-major. Array element
  addresses are always computed in 64 bits from byte strides, so arrays larger
  than 2 GiB (or with more than 2**31 elements) are addressed correctly.
- Numerics: NVRTC gets ``--ftz=false --prec-div=true --prec-sqrt=true
  --fmad=false`` unless the kernel asks for ``fast_math`` (``--use_fast_math``).
- Debug builds (``debug`` / ``verify_fp``) get a device error record; the launch
  synchronizes its stream and raises the cpu backend's ``KdslRuntimeError``.

Importing this package imports neither CuPy nor NVRTC, nor the code generator: the
runtime reads ``devices`` (the device count) without loading the backend, which loads
when ``BACKEND`` is first asked for.
"""

from typing import Any

__all__ = ["BACKEND", "CudaBackend"]


def __getattr__(name: str) -> Any:
    if name not in __all__:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    from kdsl.backends.cuda.backend import CudaBackend

    globals()["CudaBackend"] = CudaBackend
    #: The instance the ``kdsl.backends`` entry point names.
    globals()["BACKEND"] = CudaBackend()
    return globals()[name]
