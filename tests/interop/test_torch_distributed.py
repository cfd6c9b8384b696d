"""examples/distributed_torch.py (issue 19, item 2): kdsl kernels on zero-copy torch tensors in
a torch.distributed job, ghost cells and an all-reduce through gloo, and the gradient of the
loss summed over ranks through kdsl.Tape + torch autograd, checked against one process.

The two-rank run is one ``torchrun`` subprocess with a timeout; the autograd pieces are also
checked in this process against the same computation written with torch operations.
"""

import importlib
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import kdsl as wp

torch = pytest.importorskip("torch")
dist = pytest.importorskip("torch.distributed")

ROOT = Path(wp.__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "distributed_torch.py"


@pytest.fixture(scope="module")
def ex():
    if str(EXAMPLE.parent) not in sys.path:
        sys.path.insert(0, str(EXAMPLE.parent))
    return importlib.import_module("distributed_torch")


def _torch_only(u0, target, iters, a):
    """The same loss with torch operations, for torch's own gradient."""
    u = torch.tensor(u0, dtype=torch.float64, requires_grad=True)
    v = u
    for _ in range(iters):
        p = torch.cat([v.new_zeros(1), v, v.new_zeros(1)])
        v = p[1:-1] + a * (p[:-2] - 2.0 * p[1:-1] + p[2:])
    loss = torch.sum((v - torch.tensor(target)) ** 2)
    loss.backward()
    return float(loss.detach()), u.grad.numpy()


def test_one_process_loss_and_gradient_match_torch(ex):
    u0, target = ex.problem(50)
    loss, grad, _ = ex.run(ex.Neighbours(0, 1), u0, target, 5, 0.25, "cpu")
    ref_loss, ref_grad = _torch_only(u0, target, 5, 0.25)
    assert loss == pytest.approx(ref_loss, rel=1e-13)
    np.testing.assert_allclose(grad, ref_grad, rtol=1e-12, atol=1e-14)


def test_pieces_cover_the_line(ex):
    assert ex.pieces(10, 3) == [(0, 3), (3, 7), (7, 10)]


def _example_on_two_ranks(*args, timeout=180):
    """``torchrun --nproc-per-node=2 examples/distributed_torch.py ARGS``: its stdout, checked."""
    env = dict(os.environ, OMP_NUM_THREADS="1")
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc-per-node=2",
           str(EXAMPLE), *args]  # fmt: skip
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout)
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-3000:]
    assert out.stdout.strip().endswith("ok"), out.stdout
    return out.stdout


@pytest.mark.skipif(not dist.is_available(), reason="this torch build has no torch.distributed")
def test_two_gloo_ranks_match_one_process():
    out = _example_on_two_ranks("--points", "40", "--iters", "4", "--timeout", "60")
    assert "ranks=2 device=cpu" in out


@pytest.mark.skipif(
    not (torch.cuda.is_available() and torch.cuda.device_count() >= 2 and dist.is_nccl_available()),
    reason="needs two GPUs and NCCL",
)
def test_two_nccl_ranks_match_one_gpu():
    out = _example_on_two_ranks("--device", "cuda", "--points", "100000", "--iters", "8",
                                timeout=300)  # fmt: skip
    assert "ranks=2 device=cuda" in out


@wp.kernel
def _fill(a: wp.array(dtype=float), value: float):
    a[wp.tid()] = value


@pytest.mark.skipif(
    not (
        torch.cuda.is_available()
        and torch.cuda.device_count() >= 2
        and wp.get_cuda_device_count() >= 2
    ),
    reason="needs two GPUs",
)
def test_a_tensor_of_another_gpu_in_a_launch_is_an_error():
    """The usual slip of a rank: its tensor on one GPU, its launch on another."""
    t = torch.zeros(8, device="cuda:1")
    with pytest.raises(wp.KdslError, match=r"expected an array on device 'cuda:0'.*cuda:1"):
        wp.launch(_fill, dim=8, inputs=[t, 1.0], device="cuda:0")
    with pytest.raises(wp.KdslError, match=r"expected an array on device 'cuda:0'.*cuda:1"):
        wp.launch(_fill, dim=8, inputs=[wp.from_torch(t), 1.0], device="cuda:0")
    wp.launch(_fill, dim=8, inputs=[t, 1.0], device="cuda:1")
    assert float(t.sum()) == 8.0
