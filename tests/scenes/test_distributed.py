"""Strip scenes over torch.distributed (issue 19, item 4): two gloo processes on the CPU give
the undivided scene's state bit for bit; a rank that dies or stalls makes the other fail
with a ``HaloError`` within the process group's timeout, never hang.

Every process runs under a ``subprocess`` timeout as well, so a bug cannot hang CI.
The NCCL variant runs on a machine with two GPUs.
"""

import os
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

import kdsl as wp
from kdsl.scenes.binding import SceneError

torch = pytest.importorskip("torch")
dist = pytest.importorskip("torch.distributed")
if not dist.is_available():
    pytest.skip("this torch build has no torch.distributed", allow_module_level=True)

ROOT = str(Path(wp.__file__).resolve().parents[1])


def _env(**extra):
    env = dict(os.environ, **extra)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [ROOT, env.get("PYTHONPATH")]))
    env.setdefault("OMP_NUM_THREADS", "1")
    return env


def _torchrun(nproc, *args, timeout=180):
    cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone",
           f"--nproc-per-node={nproc}", *args]  # fmt: skip
    return subprocess.run(cmd, env=_env(), capture_output=True, text=True, timeout=timeout)


def test_two_gloo_ranks_equal_one_process_bit_for_bit():
    out = _torchrun(2, "-m", "kdsl.scenes.distributed", "--scene", "wave", "--integrator",
                    "velocity_verlet", "--grid", "15", "--steps", "6", "--check",
                    "--timeout", "60")  # fmt: skip
    assert out.returncode == 0, out.stderr[-3000:]
    assert "bitwise_equal=True" in out.stdout and "ranks=2" in out.stdout, out.stdout


_RANK_SCRIPT = textwrap.dedent(
    """
    import datetime, os, sys, time
    import torch.distributed as dist
    import kdsl as wp
    from kdsl.scenes.distributed import init_process_group
    from kdsl.scenes.halo import TorchHalo
    from kdsl.scenes.strips import HeatStrip

    # A patient start (ranks of a loaded machine start seconds apart), then a group whose
    # collectives time out after argv[1] seconds.
    init_process_group("cpu", timeout_s=60.0)
    halo = TorchHalo(dist.new_group(timeout=datetime.timedelta(seconds=float(sys.argv[1]))))
    scene = HeatStrip(wp, halo, grid=12)
    for step in range(10000):
        if halo.rank == 1 and step == 3:
            if sys.argv[2] == "die":
                os._exit(7)  # no word to the others
            time.sleep(120)  # stalls
        scene.step(scene.default_dt)
    """
)


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize("how", ["die", "stall"])
def test_a_rank_that_dies_or_stalls_is_an_error_not_a_hang(tmp_path, how):
    script = tmp_path / "ranks.py"
    script.write_text(_RANK_SCRIPT)
    port, procs = _free_port(), []
    for rank in range(2):
        env = _env(RANK=str(rank), WORLD_SIZE="2", LOCAL_RANK=str(rank),
                   MASTER_ADDR="127.0.0.1", MASTER_PORT=str(port))  # fmt: skip
        procs.append(subprocess.Popen([sys.executable, str(script), "3", how], env=env,
                                      stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True))  # fmt: skip
    start = time.monotonic()
    try:
        _, err = procs[0].communicate(timeout=90)
    finally:
        for p in procs:
            p.kill()
            p.communicate()
    assert procs[0].returncode != 0
    assert "HaloError: rank 0 of 2: exchanging ghost rows failed" in err, err[-3000:]
    if how == "stall":  # gloo's words for a dead peer vary (reset, closed, broken pipe)
        assert "Timed out" in err, err[-3000:]
    assert time.monotonic() - start < 85


def test_torch_halo_needs_a_process_group():
    from kdsl.scenes.halo import TorchHalo

    if dist.is_initialized():
        pytest.skip("a process group is already initialized in this process")
    with pytest.raises(SceneError, match=r"needs an initialized torch\.distributed process group"):
        TorchHalo()


def test_the_runner_needs_torchrun_and_a_known_device(monkeypatch):
    from kdsl.scenes.distributed import init_process_group

    monkeypatch.delenv("RANK", raising=False)
    with pytest.raises(SceneError, match="run under torchrun"):
        init_process_group("cpu", 10)
    monkeypatch.setenv("RANK", "0")
    with pytest.raises(SceneError, match="--device is cpu or cuda, not 'tpu'"):
        init_process_group("tpu", 10)


@pytest.mark.skipif(
    not (torch.cuda.is_available() and torch.cuda.device_count() >= 2 and dist.is_nccl_available()),
    reason="needs two GPUs and NCCL",
)
def test_two_nccl_ranks_equal_one_gpu_bit_for_bit():
    out = _torchrun(2, "-m", "kdsl.scenes.distributed", "--device", "cuda", "--scene", "heat",
                    "--integrator", "rk4", "--grid", "256", "--steps", "20", "--check")  # fmt: skip
    assert out.returncode == 0, out.stderr[-3000:]
    assert "bitwise_equal=True" in out.stdout and "ranks=2" in out.stdout, out.stdout
