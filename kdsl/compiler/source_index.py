"""The kernel cache's source index: a warm start finds a kernel without building its IR.

The kernel cache keys compiled code on the optimized IR (``cache.kernel_key``), which
takes the frontend and the pass pipeline to compute (tens of milliseconds, most of a
warm first launch). The source index maps a key computed without them to what those
steps produced, so a hit skips both:

- the **source key** (``source_key``) is a sha256 over the kernel's source fingerprint
  (``kdsl.frontend.fingerprint``: its source text and location, parameter types, and
  the digest of every global, closure value, ``@kdsl.func`` (transitively), struct and
  constant it reads), its symbol, the compile options, the backend's name, code
  version and pipeline, kdsl's own code (``kdsl_code_digest``) and ``FORMAT_VERSION``;
- an **index entry** is a small cache entry (a ``.kidx`` file, with the header and
  sha256 check of every entry) under that key holding the optimized, instrumented module
  (pickled, ops by name), its printed IR (from which the driver derives the IR key per
  target, exactly as on a miss), the instrumentation flag and the frontend's facts
  (``tid_ndim``).

Reading the kernel's source (and each called function's) is skipped too where the
index holds a **source memo** for the kernel (``load_memo``/``store_memo``): the facts
the fingerprint takes from each source (``kdsl.frontend.fingerprint.SourceFacts``),
used while each file's size and modification time are unchanged. It is keyed on the
kernel's function (file, first line, qualified name) and kdsl's code digest, stored
(JSON, a ``.ksrc`` entry) whenever a fingerprint recorded new facts.

On a hit the driver unpickles the module and hands it to the backend as if it had
just built it; the backend then loads the IR-keyed binary (or builds it from that
module if it is gone). A kernel whose fingerprint cannot be computed (it reads a value
the fingerprint cannot digest) has no index entry and is keyed by its IR as before.
Entries live in the disk cache only (``KDSL_CACHE=0`` turns the index off), and in
ahead-of-time directories beside the kernels. ``KDSL_SOURCE_INDEX=0`` turns the index
alone off (every kernel is keyed by its IR, as before; for comparisons).
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import pickle
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

from kdsl.compiler import cache as kernel_cache
from kdsl.frontend.fingerprint import SourceMemo
from kdsl.ir.catalog import CATALOG, OpDef
from kdsl.ir.core import Module

#: Bump when the index entry's layout or the source key's recipe changes.
FORMAT_VERSION = 2
#: The parts of kdsl whose code decides a kernel's IR (the backends' own code is in
#: their ``code_version``): the frontend, the IR, the passes, the compile driver, the
#: runtime's types and structs, the library of ``@kdsl.func`` functions and the
#: top-level modules (``types.py``, ``config.py``).
_CODE_DIRS = ("frontend", "ir", "passes", "compiler", "runtime", "stdlib", "geometry",
              "utils", "texture")  # fmt: skip


#: Lookups of the source index in this process (for tests and benchmarks): entries
#: found, not found, written, and found bad (then deleted).
STATS = SimpleNamespace(hits=0, misses=0, stored=0, discarded=0)


def enabled() -> bool:
    """False when ``KDSL_SOURCE_INDEX`` is 0/off/false/no."""
    flag = os.environ.get("KDSL_SOURCE_INDEX", "1").strip().lower()
    return flag not in ("0", "off", "false", "no")


@dataclass
class Entry:
    """What an index entry restores: the prepared module and what the driver needs."""

    module: Module
    ir_text: str
    checked: bool
    facts: dict[str, Any]


def kdsl_code_digest() -> str:
    """``code_digest`` of the kdsl package this process runs, taken when it was imported.

    Taken at import, not at the first compile: a kdsl file edited while a process runs
    must not key what that process (still running the old code) compiles as the new
    code's.
    """
    return _IMPORTED_CODE


def code_digest(root: str) -> str:
    """A digest of the path, size and modification time of kdsl's IR-deciding sources
    under the package directory ``root`` (its top-level modules and ``_CODE_DIRS``).

    Any edit of them (or another installed kdsl) changes it, so every source key
    misses. It reads ``stat`` alone (under a millisecond).
    """
    rows: list[str] = []
    _scan(root, rows, recurse=False)
    for sub in _CODE_DIRS:
        _scan(os.path.join(root, sub), rows, recurse=True)
    rows.sort()
    return hashlib.sha256("\n".join(rows).encode()).hexdigest()


def _scan(directory: str, rows: list[str], recurse: bool) -> None:
    """Add ``name:size:mtime`` of each ``.py`` file under ``directory`` to ``rows``."""
    try:
        entries = list(os.scandir(directory))
    except OSError:
        return
    for e in entries:
        if e.name.endswith(".py"):
            st = e.stat()
            rows.append(f"{e.path}:{st.st_size}:{st.st_mtime_ns}")
        elif recurse and e.name != "__pycache__" and e.is_dir(follow_symlinks=False):
            _scan(e.path, rows, recurse)


#: kdsl's code digest at import (see ``kdsl_code_digest``).
_IMPORTED_CODE = code_digest(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def source_key(backend: Any, fingerprint: str, symbol: str, options: dict[str, Any]) -> str:
    """The index key of a kernel (see the module docstring)."""
    doc = {
        "index": FORMAT_VERSION,
        "cache": kernel_cache.FORMAT_VERSION,
        "kdsl": kdsl_code_digest(),
        "backend": backend.name,
        "backend_version": backend.code_version(),
        "pipeline": backend.pipeline,
        "symbol": symbol,
        "options": kernel_cache.canonical(options),
        "fingerprint": fingerprint,
    }
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()


def lookup(key: str) -> Entry | None:
    """The index entry of ``key``, or None (missing, unreadable, or written by another
    version of kdsl's IR classes: then discarded)."""
    disk = _index_cache()
    if disk is None:
        return None
    payload = disk.load(key)
    if payload is None:
        STATS.misses += 1
        return None
    try:
        entry = _Unpickler(io.BytesIO(payload)).load()
        if not isinstance(entry, Entry):
            raise TypeError("not an index entry")
    except Exception:
        STATS.discarded += 1
        disk.discard(key)
        return None
    STATS.hits += 1
    return entry


def dumps(entry: Entry) -> bytes | None:
    """``entry`` as an index payload, or None when its module does not pickle (e.g. an
    attribute holding a local object: the kernel is then keyed by its IR only)."""
    out = io.BytesIO()
    try:
        _Pickler(out, protocol=pickle.HIGHEST_PROTOCOL).dump(entry)
    except Exception:
        return None
    return out.getvalue()


def store(key: str, payload: bytes) -> bool:
    """Write the index entry ``payload`` (from ``dumps``) under ``key``; False when the
    disk cache is off or unwritable."""
    disk = _index_cache()
    if disk is None or not disk.store(key, payload):
        return False
    STATS.stored += 1
    return True


def memo_key(fn: Any) -> str:
    """The key of the source memo of the kernel whose Python function is ``fn``."""
    code = fn.__code__
    doc = [FORMAT_VERSION, "memo", kdsl_code_digest(), code.co_filename, code.co_firstlineno,
           getattr(fn, "__qualname__", code.co_name)]  # fmt: skip
    return hashlib.sha256(json.dumps(doc).encode()).hexdigest()


def load_memo(fn: Any) -> SourceMemo:
    """The source memo of the kernel function ``fn`` (empty when there is none, or it is
    bad: then discarded)."""
    disk = _index_cache(kernel_cache.MEMO_SUFFIX)
    payload = disk.load(memo_key(fn)) if disk is not None else None
    if payload is None:
        return SourceMemo()
    try:
        return SourceMemo.from_json(json.loads(payload))
    except Exception:
        STATS.discarded += 1
        disk.discard(memo_key(fn))  # type: ignore[union-attr]
        return SourceMemo()


def store_memo(fn: Any, memo: SourceMemo) -> None:
    """Write ``memo`` as the source memo of the kernel function ``fn`` (best effort; not
    into an ahead-of-time directory being loaded, which is only read)."""
    disk = _index_cache(kernel_cache.MEMO_SUFFIX)
    if disk is not None and not kernel_cache.loading_aot_directory():
        disk.store(memo_key(fn), json.dumps(memo.as_json()).encode())


def _index_cache(suffix: str = kernel_cache.INDEX_SUFFIX) -> kernel_cache.DiskCache | None:
    """The index entries (or memos) beside the kernels (None when the disk cache is off)."""
    disk = kernel_cache.default_cache()
    return None if disk is None else kernel_cache.DiskCache(disk.directory, suffix)


class _Pickler(pickle.Pickler):
    """Ops' definitions are named, not copied: they hold functions (folders, rules)."""

    def persistent_id(self, obj: Any) -> Any:
        if isinstance(obj, OpDef):
            return ("op", obj.name)
        return None


#: The modules an index entry may name classes from: kdsl's IR, NumPy (constants'
#: values), Python's builtins. Anything else is refused, so loading an entry never
#: imports (runs) a module the IR does not need.
_ALLOWED_MODULES = ("kdsl.", "numpy", "builtins")


class _Unpickler(pickle.Unpickler):
    def find_class(self, module: str, name: str) -> Any:
        if not module.startswith(_ALLOWED_MODULES):
            raise pickle.UnpicklingError(f"an index entry may not name {module}.{name}")
        return super().find_class(module, name)

    def persistent_load(self, pid: Any) -> Any:
        kind, name = pid
        opdef = CATALOG.get(name) if kind == "op" else None
        if opdef is None:
            raise pickle.UnpicklingError(f"unknown op {name!r}")
        return opdef
