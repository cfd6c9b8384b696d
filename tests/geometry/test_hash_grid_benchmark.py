"""The hash-grid section of ``benchmarks/bench_geometry.py`` at a tiny size: it runs,
its radius gives the asked-for neighbour count, and its checks catch wrong answers."""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

import kdsl as wp

BENCH = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCH))

import bench_geometry_hashgrid as hg  # noqa: E402

cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")


def _args(device: str, **kw) -> argparse.Namespace:
    return argparse.Namespace(points=3000, neighbours=30.0, grid_dim=32, reps=1, device=device,
                              no_peers=True, **kw)  # fmt: skip


def test_radius_gives_the_neighbour_count():
    r = hg.radius_for(200_000, 30)
    assert 200_000 * 4 / 3 * np.pi * r**3 == pytest.approx(30)
    assert r == pytest.approx(0.0330, abs=1e-4)


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda:0", marks=cuda)])
def test_section_runs_and_agrees(device):
    rows = hg.hash_grid_section(_args(device))
    assert rows[0]["side"] == "kdsl" and rows[0]["points"] == 3000
    # Fewer than 30 near the box's faces; about 26 at this size.
    assert 22 < rows[0]["mean_neighbours"] < 30
    for r in rows:
        assert r["build_s"] > 0 and r["query_s"] > 0
    if importlib.util.find_spec("warp") is not None:
        assert [r["side"] for r in rows] == ["kdsl", "warp"]
    hg.print_hash_grid(rows)


def test_checks_catch_wrong_answers():
    pts = hg.workload(2000)
    radius = hg.radius_for(2000, 30)
    idx = np.arange(len(pts))
    counts, _ = hg.brute_counts(pts, idx, radius)
    assert hg.check_counts(counts, pts, radius) == []
    wrong = counts.copy()
    wrong[:: 7] += 1
    assert "differ from the brute force" in hg.check_counts(wrong, pts, radius)[0]
    sums = np.stack([(np.linalg.norm(pts - p, axis=1) < radius) @ pts for p in pts])
    sums = sums.astype(np.float32)
    assert hg.check_sums(sums, sums.astype(np.float64), counts, "x") == []
    off = sums.copy()
    off[5, 1] += 1e-3
    assert "kdsl vs x: neighbour sums differ" in hg.check_sums(sums, off, counts, "x")[0]


def _installed(package: str):
    return pytest.mark.skipif(importlib.util.find_spec(package) is None,
                              reason=f"{package} not installed")  # fmt: skip


@pytest.mark.parametrize("package", [pytest.param("numba", marks=_installed("numba")),
                                     pytest.param("taichi", marks=_installed("taichi"))])  # fmt: skip
def test_peer_matches_the_brute_force(package):
    impl = importlib.import_module(f"suite.hashgrid_{package}")
    pts = hg.workload(2000)
    radius = hg.radius_for(2000, 30)
    times, sums = impl.run(pts, radius, 32, 1)
    assert package == impl.NAME and times["build_s"] > 0 and times["query_s"] > 0
    p64 = pts.astype(np.float64)
    ref = np.stack([(np.linalg.norm(p64 - p, axis=1) < radius) @ p64 for p in p64])
    assert np.allclose(sums, ref, rtol=0, atol=1e-4)


def test_per_core_script_runs(tmp_path):
    """``bench_hashgrid_cores.py`` at a tiny size, in its own process (it puts kdsl's
    kernels on one thread): it checks the answers, then writes a row per side."""
    import json
    import subprocess

    out = tmp_path / "cores.json"
    args = ["--points", "2000", "--grid-dim", "16", "--reps", "1", "--rounds", "1", "--json"]
    subprocess.run([sys.executable, str(BENCH / "bench_hashgrid_cores.py"), *args, str(out)],
                   check=True, capture_output=True, timeout=600)  # fmt: skip
    table = json.loads(out.read_text())["table"]
    assert next(iter(table)) == "kdsl" and table["kdsl"]["query_s_ratio"] == 1.0
    assert all(r["build_s"] > 0 and r["query_s"] > 0 for r in table.values())
