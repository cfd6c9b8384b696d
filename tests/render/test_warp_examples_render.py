"""Warp's examples that draw with warp.render.UsdRenderer run under kdsl and write a stage."""

import importlib.util
import os
from pathlib import Path

import pytest

warp = pytest.importorskip("warp", reason="needs warp-lang (the bench extra)")
pytest.importorskip("pxr", reason="needs usd-core (the usd extra)")
from pxr import Usd  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


def _tool():
    spec = importlib.util.spec_from_file_location(
        "warp_examples", ROOT / "tools" / "warp_examples.py"
    )
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_example_wave_writes_its_usd_stage_under_kdsl(tmp_path):
    """tools/warp_examples.py's rewrite and runner, with a stage path instead of None."""
    tool = _tool()
    source = (Path(warp.__file__).parent / "examples" / "core" / "example_wave.py").read_text()
    example = tmp_path / "example_wave.py"
    example.write_text(tool.to_kdsl(source))
    stage = tmp_path / "wave.usd"
    args = tool.example_args("core/example_wave", source)
    args[args.index("--stage-path") + 1] = str(stage)
    env = {**os.environ, "KDSL_CPU_THREADS": "1"}
    res = tool.run_one(example, args, tmp_path / "run", 300, env)
    assert res["status"] == "ok", res
    usd = Usd.Stage.Open(str(stage))
    assert usd.GetPrimAtPath("/root/surface").GetTypeName() == "Mesh"
    assert usd.GetPrimAtPath("/root/sphere").GetTypeName() == "Sphere"
    points = usd.GetPrimAtPath("/root/surface").GetAttribute("points")
    assert len(points.GetTimeSamples()) == 2  # --num-frames 2
