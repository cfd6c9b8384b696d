"""Cached cpu kernels as shared objects: a warm start loads them without llvmlite."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import kdsl as wp
from kdsl.backends.cpu import host, shared_object
from kdsl.compiler import cache
from kdsl.runtime.launch import forget, launch_plan

HAS_LINKER = shared_object.linker() is not None

PROGRAM = """\
import json, sys
import kdsl as wp
from kdsl.compiler import cache

@wp.kernel
def ramp(out: wp.array(dtype=float), scale: float):
    i = wp.tid()
    out[i] = wp.sin(float(i)) * scale

out = wp.zeros(8, dtype=float)
wp.launch(ramp, 8, inputs=[out, 2.0])
key = ramp._kdsl_plans[("cpu", None)].compiled.metadata["cache_key"]
payload = cache.DiskCache(__import__("pathlib").Path(sys.argv[1])).load(key)
print(json.dumps({
    "out": out.numpy().tolist(), "builds": cache.STATS.builds,
    "disk_hits": cache.STATS.disk_hits, "llvmlite": "llvmlite.binding" in sys.modules,
    "shared": payload[:4] == b"\\x7fELF" and payload[16] == 3,
    "support_builds": cache.SUPPORT_STATS.builds,
}))
"""


def _run(tmp_path: Path, linker: str | None = None) -> dict:
    cache_dir = tmp_path / "cache"
    cache_dir.mkdir(mode=0o700, exist_ok=True)
    (tmp_path / "prog.py").write_text(PROGRAM)
    env = {**os.environ, "KDSL_CACHE_DIR": str(cache_dir)}
    env.pop("KDSL_CPU_LINKER", None)
    if linker is not None:
        env["KDSL_CPU_LINKER"] = linker
    paths = [*filter(None, os.environ.get("PYTHONPATH", "").split(os.pathsep))]
    env["PYTHONPATH"] = os.pathsep.join([str(Path(wp.__file__).resolve().parents[1]), *paths])
    done = subprocess.run(
        [sys.executable, "prog.py", str(cache_dir)], cwd=tmp_path, env=env,
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


EXPECTED = (np.sin(np.arange(8, dtype=np.float32)) * 2).tolist()


@pytest.mark.skipif(not HAS_LINKER, reason="no C compiler driver to link shared objects")
def test_a_cache_hit_loads_a_shared_object_without_llvmlite(tmp_path):
    cold = _run(tmp_path)
    assert cold["builds"] == 1 and cold["shared"] and cold["llvmlite"]
    warm = _run(tmp_path)
    assert warm["builds"] == 0 and warm["disk_hits"] == 1 and warm["support_builds"] == 0
    assert not warm["llvmlite"]  # neither the JIT nor LLVM's target queries were needed
    np.testing.assert_allclose(warm["out"], EXPECTED, rtol=1e-6)


def test_without_a_linker_the_object_file_goes_through_the_jit(tmp_path):
    cold = _run(tmp_path, linker="0")
    assert cold["builds"] == 1 and not cold["shared"]
    # A process that could link still loads the cached object file (no rebuild).
    warm = _run(tmp_path, linker=None)
    assert warm["builds"] == 0 and warm["disk_hits"] == 1 and warm["llvmlite"]
    np.testing.assert_allclose(warm["out"], EXPECTED, rtol=1e-6)


@pytest.mark.skipif(not HAS_LINKER, reason="no C compiler driver to link shared objects")
def test_a_shared_object_the_loader_rejects_is_rebuilt(tmp_path, monkeypatch):
    monkeypatch.setenv("KDSL_CACHE_DIR", str(tmp_path))

    @wp.kernel
    def plus_one(a: wp.array(dtype=float)):
        i = wp.tid()
        a[i] = a[i] + 1.0

    a = wp.zeros(4, dtype=float)
    wp.launch(plus_one, 4, [a])  # compiles and stores the entry
    key = launch_plan(plus_one, "cpu", None).compiled.metadata["cache_key"]
    # (Run alone, the process's first launch also stores the cpu pool's support code.)
    assert (tmp_path / (key + cache.SUFFIX)).is_file()
    # A valid cache entry whose payload claims to be a shared object but is not one.
    cache.DiskCache(tmp_path).store(key, b"\x7fELF" + bytes(12) + b"\x03\x00" + bytes(64))
    cache.MEMORY.clear()
    forget(plus_one)
    before = cache.STATS.discarded
    wp.launch(plus_one, 4, [a])
    assert cache.STATS.discarded == before + 1
    np.testing.assert_array_equal(a.numpy(), np.full(4, 2.0))


def test_load_refuses_what_is_not_a_shared_object():
    with pytest.raises(ValueError, match="not a shared object"):
        shared_object.load(b"\x7fELF" + bytes(12) + b"\x01\x00", ["kdsl_kernel_x"])
    assert not shared_object.is_shared_object(b"garbage")


def test_the_linker_can_be_turned_off(monkeypatch):
    shared_object.linker.cache_clear()
    try:
        monkeypatch.setenv("KDSL_CPU_LINKER", "off")
        assert shared_object.linker() is None
        shared_object.linker.cache_clear()
        monkeypatch.setenv("KDSL_CPU_LINKER", "/no/such/linker")
        assert shared_object.linker() is None
    finally:
        shared_object.linker.cache_clear()


X86 = """processor\t: 0
vendor_id\t: AuthenticAMD
cpu family\t: 25
model\t\t: 1
model name\t: AMD EPYC 7B13
cpu MHz\t\t: {mhz}
flags\t\t: fpu sse sse2 avx avx2
core id\t\t: {core}

processor\t: 1
vendor_id\t: AuthenticAMD
flags\t\t: fpu
"""


def test_the_target_is_named_by_the_fields_that_decide_code():
    a = host.cpuinfo_fields(X86.format(mhz="2450.0", core=0))
    b = host.cpuinfo_fields(X86.format(mhz="3500.1", core=7))
    assert a == b  # clock and core ids change, the target does not
    assert a["flags"] == "fpu sse sse2 avx avx2" and a["model"] == "1"
    c = host.cpuinfo_fields(X86.format(mhz="1", core=0).replace(" avx2", ""))
    assert c != a
    arm = host.cpuinfo_fields("processor : 0\nFeatures : fp asimd sve\nCPU part : 0xd40\n")
    assert arm == {"Features": "fp asimd sve", "CPU part": "0xd40"}
    assert host.target_id() == host.target_id()
