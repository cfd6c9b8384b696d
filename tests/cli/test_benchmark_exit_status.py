"""Benchmarks' own checks decide their exit status: a wrong or failed kdsl result, or
no GPU for the GPU benchmark, is a non-zero exit with the reason (issue 13)."""

import subprocess
import sys
from pathlib import Path

import pytest

import kdsl as wp

BENCH = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCH))

from suite import harness  # noqa: E402
from suite.harness import Cell  # noqa: E402


def test_wrong_kdsl_result_fails_the_benchmark(capsys):
    cells = {"saxpy": {"kdsl": Cell(status="wrong: err 1.0e-01"), "warp": Cell()},
             "jacobi": {"kdsl": Cell(), "numba": Cell(status="error: X")}}  # fmt: skip
    assert harness.exit_status(cells, "bench_cpu") == 1
    assert "bench_cpu: kdsl failed its checks: saxpy: wrong: err 1.0e-01" in capsys.readouterr().err


def test_peer_failures_do_not_fail_the_benchmark():
    cells = {"saxpy": {"kdsl": Cell(), "taichi": Cell(status="error: Y")}}
    assert harness.exit_status(cells, "bench_cpu") == 0


@pytest.mark.skipif(wp.is_cuda_available(), reason="checks the no-GPU path")
def test_gpu_benchmark_without_gpu_exits_non_zero():
    proc = subprocess.run([sys.executable, str(BENCH / "bench_cuda.py"), "--quick"],
                          capture_output=True, text=True, timeout=120)  # fmt: skip
    assert proc.returncode == 1 and "nothing measured" in proc.stderr
