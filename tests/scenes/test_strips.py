"""The grid scenes cut into row strips (issue 19, item 4): the cut, the strips stepped in one
process (``DeviceTeam``), bit-for-bit equality with the undivided scene, and the errors.

The torch.distributed runs (several processes) are in ``test_distributed.py``.
"""

import itertools
import time

import numpy as np
import pytest

import kdsl as wp
from kdsl.scenes import scene_class
from kdsl.scenes.binding import SceneError
from kdsl.scenes.halo import DeviceTeam, SingleStrip
from kdsl.scenes.strips import HeatStrip, strip_bounds, strip_scene_class


def test_strip_bounds_cover_the_rows_in_order_and_differ_by_one_at_most():
    for rows in range(1, 40):
        for parts in range(1, rows + 1):
            b = strip_bounds(rows, parts)
            assert b[0][0] == 0 and b[-1][1] == rows
            assert all(x[1] == y[0] for x, y in itertools.pairwise(b))
            sizes = [e - f for f, e in b]
            assert min(sizes) >= 1 and max(sizes) - min(sizes) <= 1
    assert strip_bounds(7, 3) == [(0, 2), (2, 4), (4, 7)]
    assert strip_bounds(4, 4) == [(0, 1), (1, 2), (2, 3), (3, 4)]
    assert strip_bounds(5, 1) == [(0, 5)]


def test_bad_cuts_and_scenes_are_scene_errors():
    with pytest.raises(SceneError, match="cannot be cut into 5 strips"):
        strip_bounds(4, 5)
    with pytest.raises(SceneError, match="at least 1 strip"):
        strip_bounds(4, 0)
    with pytest.raises(SceneError, match=r"no domain-decomposed form \(choices: heat, wave\)"):
        strip_scene_class("cloth")
    with pytest.raises(SceneError, match="at least one device"):
        DeviceTeam([])


def _whole(name, integrator, steps, **params):
    scene = scene_class(name)(wp, integrator=integrator, **params)
    for _ in range(steps):
        scene.step(scene.default_dt)
    return scene


@pytest.mark.parametrize(
    "name, integrator, strips",
    [("heat", "rk4", 3), ("heat", "backward_euler", 2), ("wave", "velocity_verlet", 2)],
)
def test_strips_on_one_device_equal_the_undivided_scene_bit_for_bit(name, integrator, strips):
    steps, grid = 6, 13

    def work(halo):
        scene = strip_scene_class(name)(wp, halo, integrator=integrator, grid=grid, jacobi_iters=8)
        for _ in range(steps):
            scene.step(scene.default_dt)
        return scene.global_state(), scene.global_error(), scene.state()[0].size

    results = DeviceTeam(["cpu"] * strips, timeout_s=60).run(work)
    whole = _whole(name, integrator, steps, grid=grid, jacobi_iters=8)
    x, v = whole.state()
    for (gx, gv), error, _ in results:  # every strip gathered the same whole state
        assert gx.tobytes() == x.tobytes()
        assert v is None or gv.tobytes() == v.tobytes()
        assert error == whole.error()
    assert [r[2] for r in results] == [grid * (b - a) for a, b in strip_bounds(grid, strips)]
    # Not bit for bit by accident: the state moved and differs from the initial one.
    assert not np.array_equal(x, whole.initial_state()[0])


def test_a_single_strip_is_the_whole_grid():
    scene = HeatStrip(wp, SingleStrip(), grid=9)
    scene.step(scene.default_dt)
    whole = _whole("heat", None, 1, grid=9)
    assert scene.global_state()[0].tobytes() == whole.state()[0].tobytes()
    assert scene.energy(*scene.state()) is None  # a strip's energy would need its neighbours


def test_a_strip_that_fails_stops_the_others_and_its_error_is_raised():
    def work(halo):
        scene = HeatStrip(wp, halo, grid=8)
        if halo.rank == 1:
            raise ValueError("strip 1 broke")
        scene.step(scene.default_dt)  # waits at the exchange for strip 1: must not hang

    start = time.monotonic()
    with pytest.raises(ValueError, match="strip 1 broke"):
        DeviceTeam(["cpu", "cpu"], timeout_s=30).run(work)
    assert time.monotonic() - start < 20


def test_a_strip_that_stalls_times_out():
    def work(halo):
        if halo.rank == 1:
            time.sleep(3.0)
        return halo.reduce_sum(1.0)

    with pytest.raises(SceneError, match=r"did not finish within 0\.5 s|timed out"):
        DeviceTeam(["cpu", "cpu"], timeout_s=0.5).run(work)


def test_reductions_and_gather_agree_on_every_strip():
    def work(halo):
        return (halo.reduce_sum(halo.rank + 1.0), halo.reduce_max(float(halo.rank)),
                [g.tolist() for g in halo.gather(np.full(halo.rank + 1, halo.rank))])  # fmt: skip

    results = DeviceTeam(["cpu"] * 3, timeout_s=30).run(work)
    assert results == [(6.0, 2.0, [[0], [1, 1], [2, 2, 2]])] * 3


two_gpus = pytest.mark.skipif(wp.get_cuda_device_count() < 2, reason="needs two CUDA devices")


@two_gpus
@pytest.mark.parametrize("peer", [False, True], ids=["through-host", "peer"])
def test_strips_on_two_gpus_equal_one_gpu_bit_for_bit(peer):
    if peer and not wp.is_peer_access_supported("cuda:0", "cuda:1"):
        pytest.skip("these GPUs have no peer access")
    steps, grid = 8, 64

    def work(halo):
        scene = HeatStrip(wp, halo, integrator="rk4", grid=grid, device=halo.device)
        for _ in range(steps):
            scene.step(scene.default_dt)
        return scene.global_state()[0]

    with (
        wp.ScopedPeerAccess("cuda:0", "cuda:1", peer),
        wp.ScopedPeerAccess("cuda:1", "cuda:0", peer),
    ):
        results = DeviceTeam(["cuda:0", "cuda:1"], timeout_s=120).run(work)
    whole = _whole("heat", "rk4", steps, grid=grid, device="cuda:0")
    assert results[0].tobytes() == whole.state()[0].tobytes()


def test_the_scaling_benchmark_runs_its_cpu_smoke_version(tmp_path):
    """benchmarks/bench_multigpu.py without GPUs: strips on the cpu device, a table and JSON."""
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    if wp.get_cuda_device_count():
        pytest.skip("with GPUs the benchmark runs at full size (tools/multigpu_check.sh)")
    root = Path(wp.__file__).resolve().parents[1]
    out = tmp_path / "multigpu.json"
    env = dict(
        os.environ,
        PYTHONPATH=os.pathsep.join(filter(None, [str(root), os.environ.get("PYTHONPATH")])),
    )
    cmd = [sys.executable, str(root / "benchmarks" / "bench_multigpu.py"), "--paths", "team",
           "--cpu-grid", "16", "--steps", "3", "--json", str(out)]  # fmt: skip
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "efficiency" in proc.stdout
    rows = json.loads(out.read_text())["scaling"]
    assert [(r["scaling"], r["ranks"], r["grid"]) for r in rows] == [
        ("strong", 1, 16),
        ("strong", 2, 16),
        ("weak", 1, 16),
        ("weak", 2, 23),
    ]
    assert all(r["ms_per_step"] > 0 and r["error"] < 1e-3 for r in rows)


def test_torch_strips_without_pytorch_say_how_to_install_it(monkeypatch):
    import sys

    from kdsl.scenes.halo import TorchHalo

    monkeypatch.setitem(sys.modules, "torch.distributed", None)  # import fails as if absent
    with pytest.raises(SceneError, match=r"pip install kdsl\[torch\]"):
        TorchHalo()


def test_the_runner_outside_torchrun_is_a_short_error():
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(wp.__file__).resolve().parents[1]
    env = {k: v for k, v in os.environ.items() if k not in ("RANK", "WORLD_SIZE")}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(root), env.get("PYTHONPATH")]))
    proc = subprocess.run([sys.executable, "-m", "kdsl.scenes.distributed", "--scene", "cloth"],
                          env=env, capture_output=True, text=True, timeout=120)  # fmt: skip
    assert proc.returncode == 2
    assert proc.stderr.startswith("kdsl.scenes.distributed: error: scene 'cloth' has no"), (
        proc.stderr
    )


def test_the_runner_refuses_too_few_steps():
    from kdsl.scenes.distributed import main

    with pytest.raises(SceneError, match="--steps must be at least 2"):
        main(["--steps", "1"])
