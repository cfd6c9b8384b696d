"""examples/distributed_jax.py (issue 19, item 3): ``jax_kernel`` and ``jax_callable`` under
``shard_map`` and ``pmap``, with ``ppermute`` (ghost cells) and ``psum`` between kdsl calls.

Four CPU devices forced in a subprocess (XLA reads ``XLA_FLAGS`` once, at start-up); on a
machine where JAX sees two GPUs or more, the same example over every GPU.
"""

import os
import subprocess
import sys
from pathlib import Path

import pytest

import kdsl as wp

jax = pytest.importorskip("jax")

ROOT = Path(wp.__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "distributed_jax.py"


def _run(**env_extra):
    env = dict(os.environ, **env_extra)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    return subprocess.run([sys.executable, str(EXAMPLE)], env=env, capture_output=True,
                          text=True, timeout=180)  # fmt: skip


def test_shard_map_and_pmap_over_four_cpu_devices():
    out = _run(XLA_FLAGS="--xla_force_host_platform_device_count=4", JAX_PLATFORMS="cpu")
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-3000:]
    lines = out.stdout.splitlines()
    assert lines[-1] == "ok", out.stdout
    for way in ("shard_map(jax_kernel)", "pmap(jax_kernel)", "pmap(jax_callable)"):
        assert f"{way}: 4 cpu devices, field bit for bit: True" in out.stdout, out.stdout


def _jax_gpus():
    try:
        return len(jax.devices("gpu"))
    except RuntimeError:
        return 0


@pytest.mark.skipif(_jax_gpus() < 2, reason="needs JAX with two GPUs")
def test_shard_map_and_pmap_over_every_gpu():
    out = _run()
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-3000:]
    assert f"pmap(jax_callable): {_jax_gpus()} gpu devices" in out.stdout, out.stdout
    assert out.stdout.splitlines()[-1] == "ok", out.stdout
