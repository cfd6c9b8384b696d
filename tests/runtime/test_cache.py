"""The kernel cache: keys, entry format, corruption, ownership, concurrency, warm starts.

Every test runs against a private ``KDSL_CACHE_DIR`` (autouse fixture in conftest).
"""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys
import threading
import time
import uuid
import warnings
from pathlib import Path

import numpy as np
import pytest

import kdsl as wp
from kdsl.backends.cpu import BACKEND
from kdsl.compiler import cache, compile_kernel
from kdsl.compiler.cache import CacheWarning, DiskCache
from kdsl.ir import print_module

POSIX = os.name == "posix"


def fresh_key() -> str:
    """A key no other test (and no JIT'd kernel) uses."""
    return cache.kernel_key(uuid.uuid4().hex, "test", "1", {}, "none")


@pytest.fixture
def disk() -> DiskCache:
    d = cache.default_cache()
    assert d is not None
    return d


# --------------------------------------------------------------------------- key


def test_key_covers_every_part():
    base = ("ir text", "cpu", "1", {"optimize": True}, "znver4;+avx2")
    k = cache.kernel_key(*base)
    assert k == cache.kernel_key(*base) and len(k) == 64
    variants = [
        ("ir text ", *base[1:]),
        (base[0], "cuda", *base[2:]),
        (*base[:2], "2", *base[3:]),
        (*base[:3], {"optimize": False}, base[4]),
        (*base[:3], {"optimize": 1}, base[4]),  # 1 is not True: types are kept apart
        (*base[:4], "znver4;-avx2"),
    ]
    keys = {cache.kernel_key(*v) for v in variants}
    assert len(keys) == len(variants) and k not in keys


KERNELS = """\
import kdsl as wp

C = wp.constant(VALUE)  # noqa: F821 (VALUE is set by the test)


@wp.kernel
def k64(out: wp.array(dtype=wp.int64)):
    i = wp.tid()
    out[i] = wp.int64(i) * wp.int64(3) + C


@wp.kernel
def ku64(out: wp.array(dtype=wp.uint64)):
    i = wp.tid()
    out[i] = wp.uint64(i) * wp.uint64(3) + wp.uint64(C)
"""


@pytest.mark.parametrize("name, dtype", [("k64", wp.int64), ("ku64", wp.uint64)])
def test_constants_are_keyed_at_full_width(tmp_path, name, dtype):
    # The same source file and kernel symbol; only the captured constant differs, by
    # 2**32: a key that hashed constants as 32-bit would reuse C = 1's code.
    path = tmp_path / "consts.py"
    path.write_text(KERNELS)
    code = compile(path.read_text(), str(path), "exec")
    keys, texts = [], []
    for value in (1, 2**32 + 1):
        ns = {"__name__": "consts", "VALUE": value}
        exec(code, ns)
        kernel = ns[name]
        compiled = compile_kernel(BACKEND, kernel.build_module(), kernel.key, kernel.options)
        keys.append(compiled.metadata["cache_key"])
        texts.append(print_module(compiled.module, debuginfo=True))
        out = wp.zeros(5, dtype=dtype)
        wp.launch(kernel, 5, outputs=[out], backend=BACKEND)
        expect = np.arange(5, dtype=np.uint64) * 3 + np.uint64(value)
        np.testing.assert_array_equal(out.numpy().astype(np.uint64), expect)
    assert texts[1].replace(str(2**32 + 1), "1") == texts[0]
    assert keys[0] != keys[1]


# --------------------------------------------------------------------------- disk layer


def test_directory_is_created_private(tmp_path, monkeypatch):
    target = tmp_path / "a" / "b" / "kdsl"
    monkeypatch.setenv("KDSL_CACHE_DIR", str(target))
    d = cache.default_cache()
    assert d is not None and d.directory == target and target.is_dir()
    if POSIX:
        assert stat.S_IMODE(target.stat().st_mode) == 0o700


def test_default_location(tmp_path, monkeypatch):
    monkeypatch.delenv("KDSL_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache.cache_dir() == tmp_path / "xdg" / "kdsl"
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert cache.cache_dir() == tmp_path / "home" / ".cache" / "kdsl"
    monkeypatch.setenv("KDSL_CACHE_DIR", str(tmp_path / "explicit"))
    assert cache.cache_dir() == tmp_path / "explicit"


def test_store_and_load(disk):
    key = fresh_key()
    assert disk.load(key) is None
    assert disk.store(key, b"\x7fELF payload")
    assert disk.load(key) == b"\x7fELF payload"
    assert [p.name for p in disk.directory.iterdir()] == [f"{key}.kobj"]  # no temporaries
    if POSIX:
        assert stat.S_IMODE(disk.path(key).stat().st_mode) & 0o077 == 0


def _truncate(data: bytes) -> bytes:
    return data[:-3]


def _flip_payload(data: bytes) -> bytes:
    return data[:-1] + bytes([data[-1] ^ 1])


def _bad_magic(data: bytes) -> bytes:
    return b"XXXXXXXX" + data[8:]


def _short(data: bytes) -> bytes:
    return data[:10]


def _empty(data: bytes) -> bytes:
    return b""


@pytest.mark.parametrize("damage", [_truncate, _flip_payload, _bad_magic, _short, _empty])
def test_a_damaged_entry_is_discarded(disk, damage):
    key = fresh_key()
    disk.store(key, b"payload bytes")
    path = disk.path(key)
    path.write_bytes(damage(path.read_bytes()))
    assert disk.load(key) is None
    assert not path.exists()


def test_an_entry_under_another_key_is_rejected(disk):
    a, b = fresh_key(), fresh_key()
    disk.store(a, b"code of a")
    os.replace(disk.path(a), disk.path(b))
    assert disk.load(b) is None


def test_a_damaged_entry_is_rebuilt_not_fatal(disk):
    key = fresh_key()
    disk.store(key, b"old")
    disk.path(key).write_bytes(b"garbage")
    calls = []
    value = cache.get_or_build(key, lambda: calls.append(1) or b"new", lambda p: p.decode())
    assert value == "new" and calls == [1]
    assert disk.load(key) == b"new"


def test_a_payload_the_loader_rejects_is_rebuilt(disk):
    key = fresh_key()
    disk.store(key, b"stale")

    def load(p: bytes) -> str:
        if p == b"stale":
            raise ValueError("not an object file")
        return p.decode()

    assert cache.get_or_build(key, lambda: b"fresh", load) == "fresh"
    assert disk.load(key) == b"fresh"


def test_memory_layer_builds_and_loads_once(disk):
    key = fresh_key()
    builds, loads = [], []

    def build() -> bytes:
        builds.append(1)
        time.sleep(0.02)  # widen the race window
        return b"code"

    def load(p: bytes) -> object:
        loads.append(1)
        return object()

    results = []
    threads = [
        threading.Thread(target=lambda: results.append(cache.get_or_build(key, build, load)))
        for _ in range(8)
    ]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert builds == [1] and loads == [1]
    assert len({id(r) for r in results}) == 1 and len(results) == 8


def test_entry_of_another_user_is_not_read(disk, monkeypatch):
    key = fresh_key()
    disk.store(key, b"mine")
    monkeypatch.setattr(cache, "_current_uid", lambda: os.getuid() + 1)
    assert disk.load(key) is None
    assert disk.path(key).exists()  # ignored, not deleted


@pytest.mark.skipif(not POSIX or os.geteuid() != 0, reason="needs root to chown")
def test_really_foreign_entry_is_not_read(disk):
    key = fresh_key()
    disk.store(key, b"mine")
    os.chown(disk.path(key), 12345, 12345)
    assert disk.load(key) is None


@pytest.mark.skipif(not POSIX, reason="symlinks and modes")
def test_symlinked_entry_is_not_followed(disk, tmp_path):
    key = fresh_key()
    other = DiskCache(tmp_path)
    other.store(key, b"elsewhere")
    disk.path(key).symlink_to(other.path(key))
    assert disk.load(key) is None


def _disabled_with_warning() -> None:
    with pytest.warns(CacheWarning):
        assert cache.default_cache() is None
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # warned once per process and directory
        assert cache.default_cache() is None


@pytest.mark.skipif(not POSIX, reason="POSIX permissions")
def test_group_writable_directory_disables_the_cache(tmp_path, monkeypatch):
    shared = tmp_path / "shared"
    shared.mkdir()
    shared.chmod(0o775)
    monkeypatch.setenv("KDSL_CACHE_DIR", str(shared))
    _disabled_with_warning()
    # Kernels still build, and nothing is written there.
    key = fresh_key()
    assert cache.get_or_build(key, lambda: b"x", lambda p: p) == b"x"
    assert list(shared.iterdir()) == []


def test_foreign_directory_disables_the_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("KDSL_CACHE_DIR", str(tmp_path / "theirs"))
    monkeypatch.setattr(cache, "_current_uid", lambda: os.getuid() + 1)
    _disabled_with_warning()


def test_uncreatable_directory_disables_the_cache(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    monkeypatch.setenv("KDSL_CACHE_DIR", str(blocker / "kdsl"))
    _disabled_with_warning()


def test_cache_off(tmp_path, monkeypatch):
    monkeypatch.setenv("KDSL_CACHE", "0")
    assert cache.default_cache() is None
    assert cache.get_or_build(fresh_key(), lambda: b"x", lambda p: p) == b"x"
    assert list(Path(os.environ["KDSL_CACHE_DIR"]).glob("*")) == []


# --------------------------------------------------------------------------- processes

KERNEL = """\
import kdsl as wp


@wp.kernel
def triple_plus(out: wp.array(dtype=wp.int64)):
    i = wp.tid()
    out[i] = wp.int64(i) * wp.int64(3) + wp.int64(7)
"""

RUN = """\
import json, sys, time
import kdsl as wp
from kdsl.backends.cpu import BACKEND
from kdsl.compiler import cache
from kern import triple_plus

start = float(sys.argv[1])
while time.time() < start:  # all processes compile at once
    time.sleep(0.002)
out = wp.zeros(16, dtype=wp.int64)
wp.launch(triple_plus, 16, outputs=[out], backend=BACKEND)
s = cache.STATS
print(json.dumps({"out": out.numpy().tolist(), "builds": s.builds, "disk_hits": s.disk_hits}))
"""


@pytest.fixture
def program(tmp_path) -> Path:
    (tmp_path / "kern.py").write_text(KERNEL)
    (tmp_path / "run.py").write_text(RUN)
    return tmp_path


def _start(program: Path, at: float) -> subprocess.Popen:
    # Keep the parent's path too: kdsl may be importable only through it (a checkout
    # run with PYTHONPATH=., as on the GPU machine).
    paths = [str(program), *filter(None, os.environ.get("PYTHONPATH", "").split(os.pathsep))]
    paths.append(str(Path(wp.__file__).resolve().parents[1]))
    # The Python thread pool: the native pool's runtime would be a second cache entry.
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(paths), "KDSL_CPU_POOL": "python"}
    return subprocess.Popen([sys.executable, str(program / "run.py"), str(at)], cwd=program,
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip


def _result(proc: subprocess.Popen) -> dict:
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err
    return json.loads(out.strip().splitlines()[-1])


EXPECTED = [3 * i + 7 for i in range(16)]


def _entries() -> list[Path]:
    """The compiled kernels' entries (the source index's ``.kidx`` entries left out);
    no temporary file may be left behind."""
    files = sorted(Path(os.environ["KDSL_CACHE_DIR"]).iterdir())
    assert not [p for p in files if p.name.endswith(".tmp")]
    return [p for p in files if p.name.endswith(".kobj")]


def test_warm_start_compiles_nothing(program):
    cold = _result(_start(program, 0))
    assert cold == {"out": EXPECTED, "builds": 1, "disk_hits": 0}
    warm = _result(_start(program, 0))
    assert warm == {"out": EXPECTED, "builds": 0, "disk_hits": 1}
    # A truncated entry is rebuilt on the next start, and valid again after.
    (entry,) = _entries()
    entry.write_bytes(entry.read_bytes()[:-100])
    assert _result(_start(program, 0)) == {"out": EXPECTED, "builds": 1, "disk_hits": 0}
    assert _result(_start(program, 0)) == {"out": EXPECTED, "builds": 0, "disk_hits": 1}


def test_concurrent_processes_share_one_entry(program):
    at = time.time() + 1.5  # after every interpreter has imported kdsl (late: a disk hit)
    procs = [_start(program, at) for _ in range(4)]
    results = [_result(p) for p in procs]
    assert all(r["out"] == EXPECTED for r in results)
    assert all(r["builds"] + r["disk_hits"] == 1 for r in results)
    (entry,) = _entries()  # one entry, no temporaries left behind
    assert entry.name.endswith(".kobj")
    key = entry.name[: -len(".kobj")]
    assert DiskCache(entry.parent).load(key) is not None


def test_same_kernel_twice_in_one_process_is_a_memory_hit(saxpy):
    before = (cache.STATS.builds, cache.STATS.memory_hits)
    a = compile_kernel(BACKEND, saxpy.build_module(), "saxpy", {"tag": "memory-test"})
    b = compile_kernel(BACKEND, saxpy.build_module(), "saxpy", {"tag": "memory-test"})
    assert a.metadata["cache_key"] == b.metadata["cache_key"]
    assert a.payload.llvm_name == b.payload.llvm_name
    assert cache.STATS.memory_hits >= before[1] + 1
    assert cache.STATS.builds <= before[0] + 1
    x = wp.array(np.arange(4, dtype=np.float32))
    y = wp.array(np.ones(4, dtype=np.float32))
    wp.launch(saxpy, 4, inputs=[x, y, 2.0], backend=BACKEND)
    np.testing.assert_allclose(y.numpy(), 2 * np.arange(4) + 1)


def test_debug_and_release_builds_are_cached_apart(saxpy):
    release = compile_kernel(BACKEND, saxpy.build_module(), "saxpy", {})
    debug = compile_kernel(BACKEND, saxpy.build_module(), "saxpy", {"debug": True})
    assert release.metadata["cache_key"] != debug.metadata["cache_key"]
