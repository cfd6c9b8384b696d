"""compile_aot_module / load_aot_module: kernels compiled into a directory, loaded by a
fresh process without compiling; get_cpu_kernel_cache_key."""

import json
import os
import subprocess
import sys
import textwrap

import pytest

import kdsl as wp

KERNELS = """
import kdsl as wp

@wp.kernel
def axpy(a: float, x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = a * x[i] + y[i]
"""

LOAD = """
import json, kdsl as wp, aot_kernels
from kdsl.compiler import cache
wp.load_aot_module("aot_kernels", "cpu", module_dir=DIR)
y = wp.ones(3)
wp.launch(aot_kernels.axpy, 3, [2.0, wp.ones(3), y])
print(json.dumps({"y": y.numpy().tolist(), "builds": cache.STATS.builds,
                  "disk_hits": cache.STATS.disk_hits}))
"""


def _run(tmp_path, code, cache_dir):
    # The Python thread pool: the native pool's runtime (support code, kept in the kernel
    # cache, not in module directories) would be an entry of the process's own cache.
    env = {**os.environ, "KDSL_CACHE_DIR": str(cache_dir), "PYTHONPATH": str(tmp_path),
           "KDSL_CPU_POOL": "python"}  # fmt: skip
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300)  # fmt: skip


def test_compile_then_load_in_a_fresh_process(tmp_path):
    (tmp_path / "aot_kernels.py").write_text(KERNELS)
    out = tmp_path / "aot"
    compiled = _run(tmp_path, f"import kdsl as wp, aot_kernels\n"
                              f"print(len(wp.compile_aot_module(aot_kernels, 'cpu', "
                              f"module_dir={str(out)!r})))", tmp_path / "cache1")  # fmt: skip
    assert compiled.returncode == 0, compiled.stderr
    assert int(compiled.stdout) == 1 and len(list(out.glob("*.kobj"))) == 1
    # A fresh process with an empty kernel cache: everything comes from the directory,
    # which loading only reads (the edit below makes the source memo stale: it is not
    # rewritten there).
    with open(tmp_path / "aot_kernels.py", "a") as f:
        f.write("# a comment added after compiling\n")
    files = {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
    loaded = _run(tmp_path, LOAD.replace("DIR", repr(str(out))), tmp_path / "cache2")
    assert loaded.returncode == 0, loaded.stderr
    result = json.loads(loaded.stdout)
    assert result == {"y": [3.0, 3.0, 3.0], "builds": 0, "disk_hits": 1}
    assert not (tmp_path / "cache2").exists() or not list((tmp_path / "cache2").glob("*.kobj"))
    assert {p.name: p.stat().st_mtime_ns for p in out.iterdir()} == files


@wp.kernel
def _probe(x: wp.array(dtype=float)):
    x[wp.tid()] = 1.5


def test_load_without_entries_refuses_to_compile(tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir(mode=0o700)
    with pytest.raises(FileNotFoundError, match="not compiled there") as info:
        wp.load_aot_module(__name__, "cpu", module_dir=empty)
    assert isinstance(info.value, wp.KdslError) and "loading module" in str(info.value)
    with pytest.raises(wp.KdslValueError, match="not a directory"):
        wp.load_aot_module(__name__, "cpu", module_dir=tmp_path / "missing")
    with pytest.raises(wp.KdslCapabilityError, match="PTX"):
        wp.compile_aot_module(__name__, "cpu", module_dir=empty, use_ptx=True)
    with pytest.raises(wp.KdslValueError, match="CUDA devices"):
        wp.compile_aot_module(__name__, "cpu", arch=90, module_dir=empty)
    # In-process round trip: compile into the directory, then load strictly from it.
    assert len(wp.compile_aot_module(__name__, "cpu", module_dir=empty)) == 1
    wp.load_aot_module(__name__, "cpu", module_dir=empty)
    x = wp.zeros(2, dtype=float)
    wp.launch(_probe, 2, [x])
    assert x.numpy().tolist() == [1.5, 1.5]
    with pytest.raises(wp.KdslTypeError, match="module must be"):
        wp.compile_aot_module(3.5)


def test_cpu_kernel_cache_key():
    key = wp.get_cpu_kernel_cache_key()
    assert key == wp.get_cpu_kernel_cache_key(cpu_compiler_flags="-march=native")
    assert key.startswith("0.1.0-") and len(key.rsplit("-", 1)[1]) == 8
    with pytest.raises(wp.KdslCapabilityError, match="host CPU"):
        wp.get_cpu_kernel_cache_key(cpu_compiler_flags="")
