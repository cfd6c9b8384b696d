"""The backend plugin interface.

A backend turns an IR module into something it can run and runs it. kdsl finds
backends through the ``kdsl.backends`` entry-point group (see ``registry``); the
built-in ones register the same way a third party does.

Launch arguments reach ``Backend.launch`` already checked and converted by the
runtime: arrays as strided NumPy-like buffers whose element shape is appended
(a ``vec3`` array of length n is an ``(n, 3)`` float32 buffer), scalars as NumPy
scalars of the parameter's exact type, vectors and matrices as NumPy arrays,
structs as tuples of field values.
"""

from __future__ import annotations

import hashlib
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from kdsl.errors import KdslLaunchError
from kdsl.ir.core import Module


@dataclass
class CompiledKernel:
    """What ``Backend.compile`` returns: one kernel, ready to launch.

    ``payload`` is the backend's own artifact (closures, a JIT handle, a CUDA
    function); the runtime never looks inside it. ``metadata["name"]``, set by
    the runtime, is the kernel's name as the user wrote it, for messages.
    """

    backend: str
    symbol: str
    module: Module
    payload: Any = None
    metadata: dict[str, Any] = field(default_factory=dict)


class Backend(ABC):
    """A code generator plus launcher for some devices. Subclass it in a plugin.

    Class attributes to set: ``name`` (the registry key, also the entry-point
    name), ``version`` (a string that goes into kernel cache keys; bump it when
    generated code changes) and ``capabilities`` ("fp64", "fp16", "atomics",
    "int64", ...), which passes, capability errors and the conformance suite read.
    """

    name: str = ""
    version: str = "0"
    capabilities: frozenset[str] = frozenset()

    @property
    def pipeline(self) -> str:
        """The pass pipeline run on a module before lowering (the standard one)."""
        return default_pipeline()

    @abstractmethod
    def devices(self) -> list[str]:
        """Names of the devices this backend runs on, e.g. ``["cpu"]``."""

    def serves(self, device: str) -> bool:
        """True when this backend can launch on ``device`` ("cpu", "cuda:0", ...)."""
        kinds = set(self.devices())
        return device in kinds or device.split(":")[0] in kinds

    @abstractmethod
    def stages(self) -> list[str]:
        """Names of the stages ``lower`` can dump, in pipeline order."""

    @abstractmethod
    def lower(self, module: Module, stage: str) -> str:
        """The module as text at ``stage`` (one of ``stages()``)."""

    @abstractmethod
    def compile(
        self, module: Module, kernel_symbol: str, options: dict[str, Any] | None = None
    ) -> CompiledKernel:
        """Optimize and compile the kernel ``kernel_symbol`` of ``module``."""

    @abstractmethod
    def launch(
        self,
        compiled: CompiledKernel,
        dims: tuple[int, ...],
        args: Sequence[Any],
        stream: Any = None,
    ) -> None:
        """Run ``compiled`` over the launch grid ``dims`` with converted ``args``."""

    def prepare(
        self,
        compiled: CompiledKernel,
        dims: tuple[int, ...],
        args: Sequence[Any],
        stream: Any = None,
    ) -> Callable[[], None]:
        """A zero-argument callable that runs this launch; called again and again.

        ``kdsl.Launch`` (``record_cmd=True``) relaunches through it. Override to pack
        arguments once; the default simply calls ``launch``.
        """
        args = list(args)
        return lambda: self.launch(compiled, dims, args, stream)

    def __repr__(self) -> str:
        return f"<kdsl backend {self.name!r} v{self.version}>"


#: The most threads one launch may have: ``tid()`` is an i32 on every built-in backend.
MAX_THREADS = 2**31 - 1


def launch_size(
    compiled: CompiledKernel, dims: Sequence[int], tid_ndims: Iterable[int], backend: str
) -> int:
    """The number of threads of the grid ``dims``, checked for a launch of ``compiled``.

    A kernel using an n-d ``tid()`` (n > 1) needs an n-d grid, and a grid may hold at
    most ``MAX_THREADS`` threads; both raise ``KdslLaunchError`` naming the kernel.
    """
    name = compiled.metadata.get("name") or compiled.symbol
    for nd in tid_ndims:
        if nd != 1 and nd != len(dims):
            raise KdslLaunchError(
                f"kernel '{name}' uses a {nd}-d thread index but was launched with "
                f"{len(dims)}-d dim={tuple(dims)}"
            )
    total = 1
    for d in dims:
        total *= int(d)
    if total > MAX_THREADS:
        raise KdslLaunchError(
            f"kernel '{name}': {total} threads is more than the "
            f"{backend} backend's limit of {MAX_THREADS}"
        )
    return total


def source_version(version: str, sources: Iterable[Path]) -> str:
    """``version`` plus a digest of a backend's ``sources``, for kernel cache keys.

    Edited code generation then never reuses stale cache entries (a developer rarely
    remembers to bump ``version``).
    """
    h = hashlib.sha256(version.encode())
    for path in sorted(sources):
        h.update(path.name.encode() + b"\0" + path.read_bytes())
    return f"{version}+{h.hexdigest()[:16]}"


def default_pipeline() -> str:
    """The standard pipeline string, or "" while kdsl.passes has none."""
    try:
        from kdsl import passes
    except ImportError:  # pragma: no cover - passes is part of kdsl
        return ""
    return getattr(passes, "DEFAULT_PIPELINE", "")


def optimize(module: Module, pipeline: str) -> Module:
    """``module`` after ``pipeline``; unchanged when the pass manager is not there.

    The pass manager may rewrite the module in place or return a new one.
    """
    if not pipeline:
        return module
    from kdsl import passes

    run = getattr(passes, "run_pipeline", None)
    if run is None:
        return module
    out = run(module, pipeline)
    return module if out is None else out
