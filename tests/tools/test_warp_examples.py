"""tools/warp_examples.py: the rewrite to kdsl, the arguments, and a run over stand-in examples."""

import importlib.util
import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "tools" / "warp_examples.py"


def _module():
    spec = importlib.util.spec_from_file_location("warp_examples", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_rewrite_changes_warp_names_only():
    mod = _module()
    src = textwrap.dedent("""\
        import warp as wp
        import warp.render
        from warp.optim import SGD  # warp stays in comments
        path = warp.examples.get_asset_directory()
        s = "import warp"
        warped = wp.warp_size
    """)
    out = mod.to_kdsl(src)
    assert out == textwrap.dedent("""\
        import kdsl as wp
        import kdsl.render
        from kdsl.optim import SGD  # warp stays in comments
        path = kdsl.examples.get_asset_directory()
        s = "import warp"
        warped = wp.warp_size
    """)
    kept = mod.to_kdsl(src, frozenset({"render", "examples"}))
    assert "import warp.render\n" in kept and "path = warp.examples" in kept
    assert "import kdsl as wp" in kept and "from kdsl.optim" in kept


def test_arguments_follow_the_examples_argparse():
    mod = _module()
    src = textwrap.dedent("""\
        parser.add_argument("--device", type=str, default=None)
        parser.add_argument(
            "--stage-path", type=lambda x: None if x == "None" else str(x), default="a.usd")
        parser.add_argument("--num-frames", type=int, default=300)
        parser.add_argument("--headless", action="store_true")
    """)
    args = mod.example_args("core/example_x", src)
    assert args == ["--device", "cpu", "--stage-path", "None", "--headless", "--num-frames", "2"]
    assert mod.example_args("core/example_y", "print(1)\n") == []
    over = mod.example_args("tile/example_tile_nbody", 'add_argument("-N", type=int)\n')
    assert over == ["-N", "128"]


def test_uses_tags():
    mod = _module()
    src = "m = wp.Mesh(p, i)\nwith wp.ScopedCapture() as c:\n    wp.launch_tiled(k)\n"
    assert mod.uses(src) == ["tiles", "geometry", "graphs"]
    assert mod.uses("wp.launch(k, dim=3)\n") == []
    guarded = textwrap.dedent("""\
        class Example:
            def __init__(self):
                self.use_cuda_graph = wp.get_device().is_cuda
                if self.use_cuda_graph:
                    with wp.ScopedCapture() as capture:
                        self.step()

                    with wp.ScopedCapture() as capture:
                        self.step()
    """)
    assert mod.uses(guarded) == ["graphs (cuda)"]
    unguarded = guarded.replace("if self.use_cuda_graph:", "if self.use_graph_capture:")
    assert mod.uses(unguarded) == ["graphs"]


EXAMPLE_OK = """\
import warp as wp

if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser()
    parser.add_argument("--device", type=str, default=None)
    parser.add_argument("--num-frames", type=int, default=100)
    args = parser.parse_known_args()[0]
    assert (args.device, args.num_frames) == ("cpu", 2), args
    print(wp.float32.__name__)
"""

EXAMPLE_ONLY_WARP = """\
import warp as wp

assert wp.__name__ == "warp", f"ran under {wp.__name__}"
"""


def test_runs_stand_in_examples(tmp_path):
    pytest.importorskip("warp", reason="needs warp-lang (the bench extra)")
    core = tmp_path / "examples" / "core"
    core.mkdir(parents=True)
    (core / "example_ok.py").write_text(EXAMPLE_OK)
    (core / "example_only_warp.py").write_text(EXAMPLE_ONLY_WARP)
    out = tmp_path / "out.json"
    proc = subprocess.run([sys.executable, str(SCRIPT), "--examples", str(tmp_path / "examples"),
                           "--groups", "core", "--timeout", "120", "--json", str(out)],
                          capture_output=True, text=True, cwd=ROOT, timeout=600)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    rows = {r["example"]: r for r in json.loads(out.read_text())["rows"]}
    assert set(rows) == {"core/example_ok", "core/example_only_warp"}
    ok, only = rows["core/example_ok"], rows["core/example_only_warp"]
    assert ok["warp_cpu"] == "yes" and ok["kdsl_status"] == "ok" and ok["done_when"]
    assert only["warp_cpu"] == "yes" and only["done_when"]
    assert only["kdsl_status"] == "AssertionError: ran under kdsl"
    assert only["kdsl"]["where"].startswith("line 3:")
    assert "kdsl runs 1 of 2" in proc.stdout
    assert "1 x `AssertionError: ran under kdsl`: core/example_only_warp" in proc.stdout
