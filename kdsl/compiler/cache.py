"""The kernel cache: compiled kernels kept on disk, so a warm start compiles nothing.

Two layers, looked up in order by ``get_or_build``:

1. memory: what this process already loaded, by key. A key is loaded at most once
   per process (loading the same object code twice into one JIT would define its
   symbols twice).
2. disk: one file per key under ``cache_dir()``. Entries are written to a temporary
   file in the same directory and published with ``os.replace`` (an atomic rename),
   so readers see a whole entry or none, and concurrent writers of one key are
   harmless (they write the same bytes; the last rename wins). Each entry has a
   header (magic, format version, key, payload length, sha256 of the payload) that
   is checked on load; a bad entry is deleted and rebuilt.

The key (``kernel_key``) is a sha256 over the optimized IR printed with debug info
(every captured constant at full precision and width), the backend's name and
version, the compile options, the target (host CPU name and features) and
``FORMAT_VERSION``. See docs/cache.md.

Environment: ``KDSL_CACHE_DIR`` (the directory; default ``$XDG_CACHE_HOME/kdsl`` or
``~/.cache/kdsl``), ``KDSL_CACHE=0`` (no disk layer; the memory layer stays).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import stat
import struct
import tempfile
import threading
import warnings
from collections.abc import Callable, Iterator, Mapping
from contextvars import ContextVar
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from kdsl.errors import KdslError

#: Bump when the entry layout or the key recipe changes.
FORMAT_VERSION = 1
MAGIC = b"KDSLKC\x00\x01"
#: magic, format version, key digest, payload length, payload sha256.
_HEADER = struct.Struct("<8sI32sQ32s")
SUFFIX = ".kobj"
#: The source index's entries (``kdsl.compiler.source_index``): same format, own suffix.
INDEX_SUFFIX = ".kidx"
#: The source index's memos of kernels' source facts (``source_index.load_memo``).
MEMO_SUFFIX = ".ksrc"
#: Backends' facts (``stored_fact``: NVRTC's version, a backend's code digest).
FACT_SUFFIX = ".kfact"
_TMP_SUFFIX = ".tmp"

T = TypeVar("T")


class CacheWarning(UserWarning):
    """The disk cache was disabled or could not write; kernels still compile."""


# --------------------------------------------------------------------------- key


def kernel_key(
    ir_text: str,
    backend: str,
    backend_version: str,
    options: Mapping[str, Any] | None,
    target: str,
) -> str:
    """The cache key (64 hex digits) of one compiled kernel.

    ``ir_text`` must be the optimized module printed with debug info; ``target``
    names what the code is compiled for (CPU name and features, GPU arch...).
    """
    doc = {
        "format": FORMAT_VERSION,
        "backend": backend,
        "backend_version": backend_version,
        "options": canonical(dict(options or {})),
        "target": target,
    }
    h = hashlib.sha256()
    h.update(json.dumps(doc, sort_keys=True).encode())
    h.update(b"\0")
    h.update(ir_text.encode())
    return h.hexdigest()


def canonical(x: Any) -> Any:
    """``x`` as JSON-able data that keeps types apart (1, 1.0 and True differ)."""
    if isinstance(x, Mapping):
        return {str(k): canonical(v) for k, v in sorted(x.items(), key=lambda kv: str(kv[0]))}
    if isinstance(x, list | tuple):
        return [canonical(v) for v in x]
    if x is None or isinstance(x, str):
        return x
    return f"{type(x).__name__}:{x!r}"


# --------------------------------------------------------------------------- location


def cache_dir() -> Path:
    """The cache directory: ``$KDSL_CACHE_DIR``, else ``$XDG_CACHE_HOME/kdsl``, else
    ``~/.cache/kdsl``."""
    explicit = os.environ.get("KDSL_CACHE_DIR")
    if explicit:
        return Path(explicit).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg).expanduser() if xdg and Path(xdg).is_absolute() else Path.home() / ".cache"
    return base / "kdsl"


def disk_cache_enabled() -> bool:
    """False when ``KDSL_CACHE`` is 0/off/false/no."""
    return os.environ.get("KDSL_CACHE", "1").strip().lower() not in ("0", "off", "false", "no")


def _current_uid() -> int | None:
    """This process's user id (None where the OS has none, e.g. Windows)."""
    getuid = getattr(os, "getuid", None)
    return None if getuid is None else getuid()


def _owned_by_me(st: os.stat_result) -> bool:
    uid = _current_uid()
    return uid is None or st.st_uid == uid


def check_directory(path: Path, create: bool = True) -> str | None:
    """None when ``path`` is safe to use as a cache directory, else why not.

    Safe: a directory owned by this user that group and others cannot write. It is
    created (mode 0700) when missing and ``create`` is set.
    """
    try:
        if create and not path.exists():
            path.mkdir(mode=0o700, parents=True, exist_ok=True)
        st = os.stat(path)
    except OSError as e:
        return f"cannot use {path}: {e.strerror or e}"
    if not stat.S_ISDIR(st.st_mode):
        return f"{path} is not a directory"
    if not _owned_by_me(st):
        return f"{path} is not owned by the current user"
    if os.name == "posix" and st.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
        return f"{path} is writable by group or others (chmod 700 it)"
    return None


# --------------------------------------------------------------------------- disk layer


@dataclass
class CacheInfo:
    """What ``DiskCache.info`` reports."""

    directory: Path
    entries: int
    total_bytes: int
    problem: str | None = None


class DiskCache:
    """Entries of one cache directory. Never raises on a bad entry or an I/O error.

    ``suffix`` tells the kinds of entries apart: compiled code (``SUFFIX``) or the
    source index (``INDEX_SUFFIX``); ``entries`` and ``info`` see one kind, ``clear``
    deletes every kind.
    """

    def __init__(self, directory: Path, suffix: str = SUFFIX) -> None:
        self.directory = Path(directory)
        self.suffix = suffix

    def path(self, key: str) -> Path:
        """The file of entry ``key``."""
        return self.directory / f"{key}{self.suffix}"

    def load(self, key: str) -> bytes | None:
        """The payload of ``key``, or None (missing, foreign, or bad: then deleted)."""
        path = self.path(key)
        flags = os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_BINARY", 0)
        try:
            fd = os.open(path, flags)
        except OSError:
            return None  # missing (the common case), or a symlink: not ours to read
        try:
            st = os.fstat(fd)
            if not stat.S_ISREG(st.st_mode) or not _owned_by_me(st):
                return None  # someone else's file: leave it unread
            with os.fdopen(fd, "rb") as f:
                fd = -1
                data = f.read()
        except OSError:
            return None
        finally:
            if fd >= 0:
                os.close(fd)
        payload = _decode(key, data)
        if payload is None:
            self.discard(key)
        return payload

    def store(self, key: str, payload: bytes) -> bool:
        """Publish ``payload`` as entry ``key`` atomically; False when it could not."""
        data = _encode(key, payload)
        try:
            fd, tmp = tempfile.mkstemp(prefix=f".{key[:16]}.", suffix=_TMP_SUFFIX,
                                       dir=self.directory)  # fmt: skip
        except OSError:
            return False
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(data)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, self.path(key))
            return True
        except OSError:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
            return False

    def discard(self, key: str) -> None:
        """Delete entry ``key`` if it is there."""
        with contextlib.suppress(OSError):
            os.unlink(self.path(key))

    def entries(self) -> list[Path]:
        """The entry files (not temporaries)."""
        try:
            return sorted(p for p in self.directory.iterdir() if p.name.endswith(self.suffix))
        except OSError:
            return []

    def info(self) -> CacheInfo:
        """Directory, number of entries and their total size."""
        files = self.entries()
        total = 0
        for p in files:
            with contextlib.suppress(OSError):
                total += p.stat().st_size
        return CacheInfo(self.directory, len(files), total)

    def clear(self) -> tuple[int, int]:
        """Delete every entry (of every kind) and leftover temporary file; gives the
        number and bytes of this kind's entries removed."""
        count = size = 0
        try:
            names = list(self.directory.iterdir())
        except OSError:
            return 0, 0
        for p in names:
            if not p.name.endswith((SUFFIX, INDEX_SUFFIX, MEMO_SUFFIX, FACT_SUFFIX, _TMP_SUFFIX)):
                continue  # never delete files the cache did not write
            try:
                n = p.stat().st_size
                p.unlink()
            except OSError:
                continue
            if p.name.endswith(self.suffix):  # counted: this kind's entries
                count += 1
                size += n
        return count, size


def _encode(key: str, payload: bytes) -> bytes:
    digest = hashlib.sha256(payload).digest()
    return _HEADER.pack(MAGIC, FORMAT_VERSION, bytes.fromhex(key), len(payload), digest) + payload


def _decode(key: str, data: bytes) -> bytes | None:
    """The payload of an entry's bytes, or None when they are not a valid entry of ``key``."""
    if len(data) < _HEADER.size:
        return None
    magic, version, kdigest, length, digest = _HEADER.unpack_from(data)
    payload = data[_HEADER.size :]
    if magic != MAGIC or version != FORMAT_VERSION or kdigest != bytes.fromhex(key):
        return None
    if length != len(payload) or hashlib.sha256(payload).digest() != digest:
        return None
    return payload


_disabled: dict[Path, str] = {}
_state_lock = threading.Lock()


# --------------------------------------------------------------------------- ahead of time


class KernelNotCompiledError(KdslError, FileNotFoundError):
    """``load_aot_module`` found no compiled entry for a kernel in its directory."""


@dataclass(frozen=True)
class _AotScope:
    directory: Path
    build: bool


_aot: ContextVar[_AotScope | None] = ContextVar("kdsl_aot_directory", default=None)


@contextlib.contextmanager
def aot_directory(directory: Path, build: bool) -> Iterator[None]:
    """Inside the block the disk layer is ``directory`` (whatever ``KDSL_CACHE`` says).

    ``build=True`` (``compile_aot_module``): every kernel looked up gets its entry there,
    even one this process had already loaded. ``build=False`` (``load_aot_module``): a
    kernel must come from memory or from ``directory``; a miss raises
    ``KernelNotCompiledError`` instead of compiling.
    """
    problem = check_directory(directory, create=build)
    if problem is not None:
        raise KdslError(f"ahead-of-time module directory: {problem}")
    token = _aot.set(_AotScope(directory, build))
    try:
        yield
    finally:
        _aot.reset(token)


def loading_aot_directory() -> bool:
    """True inside ``aot_directory(..., build=False)``: the directory is only read."""
    aot = _aot.get()
    return aot is not None and not aot.build


@contextlib.contextmanager
def outside_aot_directory() -> Iterator[None]:
    """Inside the block the disk layer is the kernel cache again, even within
    ``aot_directory`` (for backends' support code, which ahead-of-time modules leave out)."""
    token = _aot.set(None)
    try:
        yield
    finally:
        _aot.reset(token)


def default_cache() -> DiskCache | None:
    """The disk cache of the current environment, or None when it is off or unsafe.

    An unsafe directory (not ours, group/world-writable, not creatable) disables the
    disk layer for this process with one ``CacheWarning``. Inside ``aot_directory`` it
    is that directory.
    """
    aot = _aot.get()
    if aot is not None:
        return DiskCache(aot.directory)
    if not disk_cache_enabled():
        return None
    directory = cache_dir()
    with _state_lock:
        if directory in _disabled:
            return None
        problem = check_directory(directory)
        if problem is not None:
            _disabled[directory] = problem
            warnings.warn(f"kdsl kernel cache disabled: {problem}", CacheWarning, stacklevel=3)
            return None
    return DiskCache(directory)


# --------------------------------------------------------------------------- memory layer


class MemoryCache:
    """What this process loaded, by key; each key is built or loaded at most once."""

    def __init__(self) -> None:
        self._values: dict[str, Any] = {}
        self._locks: dict[str, threading.Lock] = {}
        self._lock = threading.Lock()

    def __contains__(self, key: str) -> bool:
        return key in self._values

    def __len__(self) -> int:
        return len(self._values)

    def get(self, key: str) -> Any:
        """The value of ``key``, or None."""
        return self._values.get(key)

    def lock(self, key: str) -> threading.Lock:
        """The lock that serializes building ``key`` in this process."""
        with self._lock:
            return self._locks.setdefault(key, threading.Lock())

    def put(self, key: str, value: Any) -> None:
        """Remember ``value`` for ``key``."""
        self._values[key] = value

    def clear(self) -> None:
        """Forget every value (``kdsl.clear_kernel_cache``): each key is built again."""
        with self._lock:
            self._values.clear()


MEMORY = MemoryCache()


@dataclass
class Stats:
    """Counters of this process's lookups, for tests and ``kdsl cache info``."""

    memory_hits: int = 0
    disk_hits: int = 0
    builds: int = 0
    discarded: int = 0


STATS = Stats()
#: The same counters for backends' support code (``kdsl.compiler.load_support``).
SUPPORT_STATS = Stats()


#: Lookups of facts backends keep in the cache (``stored_fact``).
FACT_STATS = Stats()


def stored_fact(name: str, learn: Callable[[], bytes]) -> bytes:
    """A backend's fact (``kdsl.backends.facts``) kept in the kernel cache as an entry.

    Entries are keyed on ``name`` alone (the backend names a fact after what decides
    it); ahead-of-time directories never hold them.
    """
    key = kernel_key("", "facts", str(FORMAT_VERSION), {"fact": name}, "")
    with outside_aot_directory():
        return get_or_build(key, learn, bytes, FACT_STATS, FACT_SUFFIX)


def get_or_build(
    key: str,
    build: Callable[[], bytes],
    load: Callable[[bytes], T],
    stats: Stats | None = None,
    suffix: str = SUFFIX,
) -> T:
    """The loaded value of ``key``: from memory, else from disk, else built and stored.

    ``build()`` makes the payload (object code); ``load(payload)`` turns it into the
    value kept in memory (e.g. a function address). A disk payload that ``load``
    rejects by raising is discarded and rebuilt. Lookups count in ``stats`` (default
    ``STATS``, the kernels' counters); entries are files ending in ``suffix``.
    """
    if stats is None:
        stats = STATS
    value = MEMORY.get(key)
    aot = _aot.get()
    if value is not None and (aot is None or not aot.build):
        stats.memory_hits += 1
        return value
    if value is not None:  # compile_aot_module: loaded here, but the directory needs it
        disk = DiskCache(aot.directory, suffix)  # type: ignore[union-attr]
        if disk.load(key) is None and not disk.store(key, build()):
            raise KdslError(f"compile_aot_module: could not write to {disk.directory}")
        return value
    with MEMORY.lock(key):
        value = MEMORY.get(key)
        if value is not None:
            stats.memory_hits += 1
            return value
        disk = default_cache()
        if disk is not None and suffix != SUFFIX:
            disk = DiskCache(disk.directory, suffix)
        payload = disk.load(key) if disk is not None else None
        if payload is not None:
            try:
                value = load(payload)
                stats.disk_hits += 1
            except Exception:
                stats.discarded += 1
                disk.discard(key)  # type: ignore[union-attr]
                value = None
        if value is None and aot is not None and not aot.build:
            raise KernelNotCompiledError(
                f"no ahead-of-time compiled entry {key[:16]}... in {aot.directory}: this kernel "
                f"(with these options, on this target) was not compiled there by "
                f"compile_aot_module; compile it first, or launch it normally to compile now"
            )
        if value is None:
            payload = build()
            stats.builds += 1
            if disk is not None and not disk.store(key, payload):
                warnings.warn(f"kdsl kernel cache: could not write to {disk.directory}",
                              CacheWarning, stacklevel=2)  # fmt: skip
            value = load(payload)
        MEMORY.put(key, value)
        return value
