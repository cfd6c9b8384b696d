"""The cuda cache key names NVRTC without loading it: a fingerprint of its library file.

Runs without a GPU (kernels are compiled for sm_90 and never loaded on a device).
Checked: a cache hit in a fresh process does not load ``libnvrtc`` (nor import
CuPy); another library file gives another fingerprint, another key; NVRTC's version
and architectures are asked once per library and then read from the kernel cache.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

pytest.importorskip("cupy_backends.cuda.libs.nvrtc")

from kdsl.backends.cuda import BACKEND, nvrtc
from kdsl.compiler import cache

ROOT = Path(__file__).resolve().parents[2]
_CACHED = (nvrtc.version, nvrtc.supported_archs, nvrtc.toolchain_facts, nvrtc.library_fingerprint)


@pytest.fixture
def fresh_nvrtc_facts():
    """The process-wide answers forgotten before and after the test (as a new process)."""
    for f in _CACHED:
        f.cache_clear()
    yield
    for f in _CACHED:
        f.cache_clear()


@pytest.fixture
def fake_library(tmp_path, monkeypatch, fresh_nvrtc_facts):
    """A directory holding a stand-in ``libnvrtc.so.13``, the only place searched."""
    lib_dir = tmp_path / "lib"
    lib_dir.mkdir()
    lib = lib_dir / "libnvrtc.so.13"
    lib.write_bytes(b"\x7fELF one nvrtc")
    monkeypatch.setattr(nvrtc, "_search_dirs", lambda: [str(lib_dir)])
    monkeypatch.setenv("KDSL_CACHE_DIR", str(tmp_path / "cache"))
    return lib


def _forget() -> None:
    """What a new process starts without: the in-process answers and memory cache."""
    for f in _CACHED:
        f.cache_clear()
    cache.MEMORY.clear()


def test_another_library_file_changes_the_fingerprint_and_the_key(fake_library, monkeypatch):
    asked = []
    answer = {"version": "13.5", "archs": [75, 80, 90]}
    monkeypatch.setattr(nvrtc, "_ask_nvrtc", lambda: asked.append(1) or json.dumps(answer).encode())
    first_fp, first_key = nvrtc.library_fingerprint(), BACKEND.cache_target("sm_90")
    assert first_fp is not None and first_key == f"sm_90/nvrtc-13.5-{first_fp}"
    fake_library.write_bytes(b"\x7fELF another nvrtc, same version")
    _forget()
    assert nvrtc.library_fingerprint() != first_fp
    assert BACKEND.cache_target("sm_90") != first_key
    assert len(asked) == 2  # each library is asked once


def test_facts_are_asked_once_per_library_then_read_from_the_cache(fake_library, monkeypatch):
    asked = []
    answer = {"version": "12.8", "archs": [80, 86, 89, 90]}
    monkeypatch.setattr(nvrtc, "_ask_nvrtc", lambda: asked.append(1) or json.dumps(answer).encode())
    assert nvrtc.version() == "12.8" and nvrtc.supported_archs() == (80, 86, 89, 90)
    assert nvrtc.arch_for(87) == "sm_86"
    for _ in range(2):
        _forget()  # a fresh process: the answer comes from the disk cache
        assert nvrtc.version() == "12.8" and nvrtc.supported_archs() == (80, 86, 89, 90)
    assert len(asked) == 1
    fake_library.unlink()  # no library found: no fingerprint, NVRTC is asked every time
    _forget()
    assert nvrtc.library_fingerprint() is None
    assert BACKEND.cache_target("sm_90") == "sm_90/nvrtc-12.8"
    assert len(asked) == 2


def test_the_real_library_gives_the_real_answers(fresh_nvrtc_facts, tmp_path, monkeypatch):
    monkeypatch.setenv("KDSL_CACHE_DIR", str(tmp_path))
    lib = nvrtc._nvrtc()
    major, minor = lib.getVersion()
    assert nvrtc.version() == f"{major}.{minor}"
    assert nvrtc.supported_archs() == tuple(lib.getSupportedArchs())


_WARM = textwrap.dedent(
    """
    import sys
    from kdsl.backends.cuda import BACKEND, nvrtc
    from kdsl.compiler import cache, compile_kernel
    from kdsl.testing.cases.programs import make_programs

    k = compile_kernel(BACKEND, make_programs()["saxpy"], options={"arch": "sm_90"})
    k.payload.cubin("sm_90")
    maps = open("/proc/self/maps").read()
    print("fingerprint", nvrtc.library_fingerprint() is not None)
    print("builds", cache.STATS.builds, "disk_hits", cache.STATS.disk_hits)
    print("libnvrtc", "libnvrtc.so" in maps, "cupy", "cupy" in sys.modules)
    """
)


def _lines(cmd: list[str], env: dict) -> list[str]:
    run = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True, cwd=ROOT)
    return run.stdout.splitlines()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/self/maps")
def test_a_cache_hit_in_a_fresh_process_does_not_load_libnvrtc(tmp_path):
    env = {**os.environ, "KDSL_CACHE_DIR": str(tmp_path), "PYTHONPATH": str(ROOT)}
    cold, warm = (_lines([sys.executable, "-c", _WARM], env) for _ in range(2))
    if "fingerprint False" in warm:
        pytest.skip("no libnvrtc file where CuPy looks: the key asks NVRTC itself")
    assert "builds 1 disk_hits 0" in cold and "libnvrtc True cupy True" in cold
    assert "builds 0 disk_hits 1" in warm
    assert "libnvrtc False cupy False" in warm
