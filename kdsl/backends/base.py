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
import os
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from kdsl.backends.facts import stored_fact
from kdsl.errors import KdslError, KdslLaunchError
from kdsl.ir.core import Block, Module, Operation, Value
from kdsl.passes import DEFAULT_PIPELINE

#: A launch grid: the extent of each dimension (one to four of them).
Dims = tuple[int, ...]
#: Launch arguments, converted by the runtime (see the module docstring).
Args = Sequence[Any]


@dataclass
class CompiledKernel:
    """What ``Backend.load`` returns: one kernel, ready to launch.

    ``payload`` is the backend's own artifact (closures, a JIT handle, a CUDA
    function); the runtime never looks inside it. ``metadata["name"]``, set by
    the runtime, is the kernel's name as the user wrote it, for messages.
    """

    backend: str
    symbol: str
    module: Module
    payload: Any = None
    metadata: dict[str, Any] = field(default_factory=dict)


@dataclass
class Job:
    """One kernel on its way through a backend, as the compile driver hands it over.

    ``module`` is optimized and instrumented; ``checked`` says instrumentation (bounds
    or NaN/Inf checks) was inserted, so launches must read an error record.
    ``artifact(target)`` is the loaded binary for ``target``, which the driver takes
    from the kernel cache or has the backend ``build``; ``key(target)`` is its cache key
    (a digest: equal keys are equal code, so it can name symbols uniquely).
    """

    module: Module
    symbol: str
    options: dict[str, Any]
    checked: bool
    artifact: Callable[[str], Any]
    key: Callable[[str], str]
    #: The backend's own notes on this job (e.g. generated source that ``load`` made and
    #: ``build`` reuses on a cache miss).
    notes: dict[str, Any] = field(default_factory=dict)


@dataclass
class SupportCode:
    """Native code a backend needs besides its kernels (a runtime), cached like a kernel.

    The compile driver (``kdsl.compiler.load_support``) keys it on ``text`` (its source),
    the backend's name and code version and ``target``, calls ``build()`` on a cache miss
    and ``load(payload)`` once per process. ``optional``: a failure to build or load is
    a warning, and the backend works without it.
    """

    name: str
    text: str
    target: str
    build: Callable[[], bytes]
    load: Callable[[bytes], Any]
    optional: bool = True


class Backend(ABC):
    """A code generator plus launcher for some devices. Subclass it in a plugin.

    A backend declares what it is and implements emission, loading and launching; the
    compile driver (``kdsl.compiler``) runs the passes, keys the kernel cache and calls
    these methods in order (see docs/backends.md):

    - ``pipeline``: the pass pipeline run on a module before emission (data).
    - ``emit(module, stage, options, checked)``: the text of one of ``emit_stages``.
    - ``build(job, target) -> bytes``: the binary of ``job`` for ``target`` (a cache miss).
    - ``load_artifact(job, target, data)``: bytes to something runnable, once per process.
    - ``load(job) -> CompiledKernel``: the launchable kernel; it asks ``job.artifact(target)``.
    - ``launch`` / ``prepare``: run a compiled kernel over a grid.

    Class attributes to set: ``name`` (the registry key, also the entry-point name),
    ``version`` (a string that goes into kernel cache keys; bump it when generated code
    changes), ``capabilities`` ("fp64", "fp16", "atomics", "int64", ...), which passes,
    capability errors and the conformance suite read, and ``emit_stages``.
    """

    name: str = ""
    version: str = "0"
    capabilities: frozenset[str] = frozenset()
    #: The pass pipeline run on a module before emission (the standard one by default).
    pipeline: str = DEFAULT_PIPELINE
    #: The stages ``emit`` prints, in pipeline order, after the driver's "kir", "kir-opt".
    emit_stages: tuple[str, ...] = ()
    #: False for a backend with no binary to cache (an interpreter): ``load`` then never
    #: calls ``job.artifact``.
    cacheable: bool = True
    #: Options that select the target rather than change the code (left out of cache keys
    #: as options; the target itself is in the key).
    target_options: tuple[str, ...] = ()

    @abstractmethod
    def devices(self) -> list[str]:
        """Names of the devices this backend runs on, e.g. ``["cpu"]``."""

    def serves(self, device: str) -> bool:
        """True when this backend can launch on ``device`` ("cpu", "cuda:0", ...)."""
        kinds = set(self.devices())
        return device in kinds or device.split(":")[0] in kinds

    def stages(self) -> list[str]:
        """Every stage ``kdsl ir`` can print for this backend, in pipeline order."""
        return ["kir", "kir-opt", *self.emit_stages]

    def code_version(self) -> str:
        """The version that keys the kernel cache (``version``; see ``source_version``)."""
        return self.version

    def cache_target(self, target: str) -> str:
        """``target`` as the cache key names it (add compiler versions here)."""
        return target

    def emit(self, module: Module, stage: str, options: dict[str, Any], checked: bool) -> str:
        """The prepared ``module`` as text at ``stage`` (one of ``emit_stages``)."""
        raise KdslError(f"the {self.name} backend has no stage {stage!r}")

    def build(self, job: Job, target: str) -> bytes:
        """The binary of ``job`` for ``target``."""
        raise NotImplementedError(f"the {self.name} backend builds no binaries")

    def load_artifact(self, job: Job, target: str, data: bytes) -> Any:
        """``data`` (from ``build`` or the disk cache) made runnable; the bytes by default.

        The result is kept per cache key for the process and handed to every later job of
        that key, so it must depend only on ``data`` and ``target`` (bind per-job objects
        such as the module's ops in ``load``); ``job`` is given for names derived from
        ``job.key(target)``.
        """
        return data

    @abstractmethod
    def load(self, job: Job) -> CompiledKernel:
        """The launchable kernel of ``job``: its binary comes from ``job.artifact(target)``."""

    @abstractmethod
    def launch(self, compiled: CompiledKernel, dims: Dims, args: Args, stream: Any = None) -> None:
        """Run ``compiled`` over the launch grid ``dims`` with converted ``args``."""

    def prepare(
        self, compiled: CompiledKernel, dims: Dims, args: Args, stream: Any = None
    ) -> Callable[[], None]:
        """A zero-argument callable that runs this launch; called again and again.

        ``kdsl.Launch`` (``record_cmd=True``) relaunches through it. Override to pack
        arguments once; the default simply calls ``launch``.
        """
        args = list(args)
        return lambda: self.launch(compiled, dims, args, stream)

    def prepare_reusable(
        self, compiled: CompiledKernel, dims: Dims, args: Args, stream: Any = None
    ) -> Callable[[], None] | None:
        """Like ``prepare``, but the callable must not keep ``args``' buffers alive.

        A plain ``launch`` whose arguments match an earlier one's calls it instead of
        ``launch`` (``kdsl.runtime.launch_reuse``); the runtime checks that every buffer
        is still alive before each call, so the callable may hold raw pointers into
        them. None (the default) means the backend packs every launch afresh.
        """
        return None

    def prepare_patchable(
        self, compiled: CompiledKernel, dims: Dims, args: Args, stream: Any = None,
        values: Sequence[int] = (),
    ) -> tuple[Callable[[], None], Callable[[Sequence[Any]], None]] | None:  # fmt: skip
        """``prepare_reusable`` whose by-value parameters can change: (run, write).

        ``values`` are the indices (ascending) of the scalar, vector, matrix and handle
        parameters; ``write(new)`` puts new converted values of those parameters (one per
        index) into the packed launch, in place, for the next ``run()``. The runtime
        calls ``write`` only between runs and from one thread, so a backend may patch
        its one buffer, provided a ``run`` has finished reading it when it returns (a
        cpu launch runs synchronously; ``cuLaunchKernel`` copies its parameters). None
        (the default) means the launch cannot be patched.
        """
        return None

    def support(self) -> list[SupportCode]:
        """Native support code to load before the first launch (none by default)."""
        return []

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
    check_tid_ndims(name, dims, tid_ndims)
    total = 1
    for d in dims:
        total *= int(d)
    if total > MAX_THREADS:
        raise KdslLaunchError(
            f"kernel '{name}': {total} threads is more than the "
            f"{backend} backend's limit of {MAX_THREADS}"
        )
    return total


def check_tid_ndims(kernel: str, dims: Sequence[int], tid_ndims: Iterable[int]) -> None:
    """Raise ``KdslLaunchError`` if ``kernel`` uses an n-d ``tid()`` (n > 1) on a grid not n-d."""
    for nd in tid_ndims:
        if nd != 1 and nd != len(dims):
            raise KdslLaunchError(
                f"kernel '{kernel}' uses a {nd}-d thread index but was launched with "
                f"{len(dims)}-d dim={tuple(dims)}"
            )


def split_block(block: Block) -> tuple[list[Operation], list[Value]]:
    """The ops of ``block`` that lower one by one (all but its terminator), and the values
    the terminator yields (none without one): what every backend's block lowering reads."""
    term = block.terminator
    if term is None:
        return list(block.ops), []
    return block.ops[:-1], list(term.operands)


#: Sources modified less than this many seconds ago are digested every time (see
#: ``source_version``): a file system's clock ticks at most this coarsely.
SETTLED_S = 2.0


def package_sources(directory: str | Path) -> list[str]:
    """The ``.py`` files directly in ``directory``, for ``source_version`` (``os.scandir``:
    a ``pathlib`` glob costs more than the rest of a warm ``source_version``)."""
    with os.scandir(directory) as entries:
        return [e.path for e in entries if e.name.endswith(".py")]


def source_version(version: str, sources: Iterable[str | Path]) -> str:
    """``version`` plus a digest of a backend's ``sources``, for kernel cache keys.

    Edited code generation then never reuses stale cache entries (a developer rarely
    remembers to bump ``version``). Reading and hashing every file costs about 0.7 ms of
    a warm compile, so the digest is kept as a fact (``facts.stored_fact``) named after
    the files' paths, sizes and modification times: a warm process ``stat``s them and
    reads one small entry. The digest is of the contents either way, so equal sources
    give equal keys on any machine. A file modified in the last ``SETTLED_S`` seconds
    is read every time: an edit within the same clock tick as the recorded one would
    keep its size and time.
    """
    paths = sorted(map(str, sources))
    stats = [os.stat(p) for p in paths]

    def digest() -> bytes:
        h = hashlib.sha256(version.encode())
        for path in paths:
            with open(path, "rb") as f:
                h.update(os.path.basename(path).encode() + b"\0" + f.read())
        return h.hexdigest()[:16].encode()

    if time.time_ns() - max((st.st_mtime_ns for st in stats), default=0) < SETTLED_S * 1e9:
        return f"{version}+{digest().decode()}"
    where = repr([version, *((p, st.st_size, st.st_mtime_ns) for p, st in zip(paths, stats))])
    name = f"source-version-{hashlib.sha256(where.encode()).hexdigest()[:32]}"
    return f"{version}+{stored_fact(name, digest).decode()}"
