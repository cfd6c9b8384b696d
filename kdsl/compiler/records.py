"""What the compile driver compiled: ``record_compiles()`` collects one record per kernel.

``kdsl scene info`` (and anyone asking "what did this program compile, and what did
it cost?") runs code inside ``with record_compiles() as records:``; every
``compile_kernel`` call made meanwhile appends a ``CompileRecord``: the kernel's
symbol, the backend, the seconds the compile took (frontend, passes and the
backend's build, or the cache's load), whether the backend built code (a cache miss),
the size of the binary it built, the op count and the feature analysis of the
optimized module (``kdsl.passes.features``), and whether it is a kernel's adjoint.
Outside a ``record_compiles`` block the driver records nothing and pays nothing.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

from kdsl.ir import Module
from kdsl.passes.features import Features, analyze_features


@dataclass(frozen=True)
class CompileRecord:
    """One compiled kernel (see the module docstring)."""

    symbol: str
    backend: str
    #: Wall seconds of ``compile_kernel``: frontend, passes, then build or cache load.
    seconds: float
    #: True when the backend built the code (False: the kernel cache had it).
    built: bool
    #: Bytes of the binary the backend built (object code, PTX); None when it built
    #: none (a cache hit, or a backend without binaries such as ``interp``).
    code_bytes: int | None
    #: Operations in the optimized module (every function, nested ops included).
    op_count: int
    features: Features

    @property
    def adjoint(self) -> bool:
        """True for a kernel's adjoint (or its tape counter)."""
        return "adjoint" in self.features


_lock = threading.Lock()
_active: list[list[CompileRecord]] = []


def recording() -> bool:
    """True while some ``record_compiles`` block is open (the driver's cheap test)."""
    return bool(_active)


def add_record(symbol: str, backend: str, seconds: float, module: Module,
               built_bytes: list[int]) -> None:  # fmt: skip
    """Append a record of one compile to every open ``record_compiles`` list."""
    record = CompileRecord(
        symbol, backend, seconds, bool(built_bytes), sum(built_bytes) if built_bytes else None,
        sum(1 for _ in module.walk()), analyze_features(module),
    )  # fmt: skip
    with _lock:
        for records in _active:
            records.append(record)


@contextmanager
def record_compiles() -> Iterator[list[CompileRecord]]:
    """Collect a ``CompileRecord`` for each kernel compiled inside the block."""
    records: list[CompileRecord] = []
    with _lock:
        _active.append(records)
    try:
        yield records
    finally:
        with _lock:
            _active.remove(records)
