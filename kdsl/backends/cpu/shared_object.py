"""Kernels as shared objects: linked once by the system's C compiler, loaded by ``ctypes``.

The kernel cache keeps what ``CpuBackend.build`` returns. Where a linker is found,
that is a shared object: the kernel's position-independent object code linked with
``ld -shared``. A cache hit then loads it with ``dlopen`` (from a file of a private
directory, so the bytes the cache checked are the bytes loaded) and needs no part of llvmlite,
whose binding library alone costs about 25 ms to import. Without a linker (or with
``KDSL_CPU_LINKER=0``) the cache keeps the object file, which llvmlite's JIT loads,
as before; a cache holding shared objects is loaded the same way on any host of the
same target, linker or not.

``KDSL_CPU_LINKER`` names the program to link with, ``ld`` or a compiler driver
(default: ``ld`` on the ``PATH``, falling back to ``cc`` for a kernel ``ld`` alone
cannot link; else ``cc``, ``gcc``, ``clang``); ``0``/``off`` turns shared objects off.
Linux only: elsewhere kernels go through llvmlite's JIT.
"""

from __future__ import annotations

import atexit
import ctypes
import functools
import os
import shutil
import sys
import tempfile
import threading
from pathlib import Path
from typing import Any

#: ``e_type`` of an ELF shared object, at bytes 16-17 of the header.
_ET_DYN = 3
#: Handles of the loaded kernels: never closed, as JIT code is never freed.
_LOADED: list[Any] = []
_LOCK = threading.Lock()
#: Shared objects ``link`` loaded to check them, by their bytes: the ``load`` that
#: follows a build takes the handle instead of loading a second copy.
_VERIFIED: dict[bytes, Any] = {}
#: The longest a link may take (a linker that hangs must not hang the compile).
LINK_TIMEOUT_S = 60


@functools.cache
def linker() -> str | None:
    """The program that links kernels (``ld`` or a compiler driver), or None (off)."""
    if not sys.platform.startswith("linux"):
        return None
    choice = os.environ.get("KDSL_CPU_LINKER", "").strip()
    if choice.lower() in ("0", "off", "false", "no"):
        return None
    if choice:
        return shutil.which(choice)
    for name in ("ld", "cc", "gcc", "clang"):
        found = shutil.which(name)
        if found:
            return found
    return None


def _commands(obj: Path, out: Path) -> list[list[str]]:
    """The link commands to try in order: ``ld`` itself (four times faster than going
    through a compiler driver), then the driver, which also links its runtime library
    (the float16 conversions some kernels call)."""
    chosen = linker()
    if chosen is None:
        return []
    # -Bsymbolic: calls between the kernel's own functions never go to another
    # library's symbol of the same name. libm: the math functions kernels call.
    as_ld = [str(out), str(obj), "-lm", "-Bsymbolic"]
    as_driver = [str(out), str(obj), "-lm", "-Wl,-Bsymbolic"]
    if Path(chosen).name.startswith("ld"):
        driver = None if os.environ.get("KDSL_CPU_LINKER") else shutil.which("cc")
        cmds = [[chosen, "-shared", "-o", *as_ld]]
        return cmds + ([[driver, "-shared", "-o", *as_driver]] if driver else [])
    return [[chosen, "-shared", "-o", *as_driver]]


def is_shared_object(data: bytes) -> bool:
    """True when ``data`` is an ELF shared object (what ``link`` makes)."""
    return data[:4] == b"\x7fELF" and int.from_bytes(data[16:18], "little") == _ET_DYN


def link(obj: bytes) -> bytes | None:
    """``obj`` (position-independent object code) linked into a shared object that loads.

    None when there is no linker, it fails, or what it made does not load here (a
    symbol no library provides): the caller keeps the object file.
    """
    import subprocess  # a miss only: its import (5 ms) stays off the warm start

    with tempfile.TemporaryDirectory(prefix="kdsl-link-") as tmp:
        src, out = Path(tmp) / "kernel.o", Path(tmp) / "kernel.so"
        src.write_bytes(obj)
        for cmd in _commands(src, out):
            try:
                done = subprocess.run(cmd, capture_output=True, timeout=LINK_TIMEOUT_S)
            except (OSError, subprocess.SubprocessError):
                continue
            if done.returncode != 0 or not out.exists():
                continue
            data = out.read_bytes()
            try:
                lib = _dlopen(data)  # every symbol resolves (ctypes loads with RTLD_NOW)
            except OSError:
                continue
            with _LOCK:
                _VERIFIED[data] = lib  # ``load`` of these very bytes uses this handle
            return data
    return None


def load(data: bytes, symbols: list[str]) -> dict[str, int]:
    """Load the shared object ``data``; gives the address of each of ``symbols``.

    Raises ``ValueError`` when ``data`` is not a shared object of this host or lacks a
    symbol (the kernel cache then discards the entry and rebuilds it).
    """
    if not is_shared_object(data):
        raise ValueError("not a shared object")
    with _LOCK:
        lib = _VERIFIED.pop(data, None)
    try:
        if lib is None:
            lib = _dlopen(data)
        out = {s: ctypes.cast(getattr(lib, s), ctypes.c_void_p).value for s in symbols}
    except (OSError, AttributeError) as e:
        raise ValueError(f"cannot load the shared object: {e}") from None
    missing = [s for s, address in out.items() if not address]
    if missing:
        raise ValueError(f"the shared object lacks {missing}")
    with _LOCK:
        _LOADED.append(lib)
    return out  # type: ignore[return-value]


def _dlopen(data: bytes) -> ctypes.CDLL:
    """``dlopen`` of ``data``, written to a file of this process's private directory.

    Each load gets a path never used before: ``dlopen`` returns an already loaded
    library when given its path again, so reusing a name (a memory file's
    ``/proc/self/fd/N``, whose numbers come back) could hand out another kernel.
    The file is removed once loaded; the mapping stays.
    """
    global _LOAD_COUNT
    with _LOCK:
        _LOAD_COUNT += 1
        path = _private_dir() / f"kernel-{_LOAD_COUNT}.so"
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view) :]
    finally:
        os.close(fd)
    try:
        return ctypes.CDLL(str(path))
    finally:
        path.unlink()


_LOAD_COUNT = 0


@functools.cache
def _private_dir() -> Path:
    """A directory only this process writes to (mode 0700), removed at exit."""
    path = Path(tempfile.mkdtemp(prefix="kdsl-kernels-"))
    atexit.register(shutil.rmtree, path, True)
    return path
