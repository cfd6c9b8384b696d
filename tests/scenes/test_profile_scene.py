"""benchmarks/profile_scene.py: a scene's step timed and profiled (on the cpu here)."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _profile(*args: str) -> subprocess.CompletedProcess:
    cmd = [sys.executable, str(ROOT / "benchmarks" / "profile_scene.py"), *args]
    return subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)


def test_profile_scene_prints_the_step_time_and_both_tables():
    proc = _profile("chain", "--steps", "3", "--rows", "4")
    assert proc.returncode == 0, proc.stderr
    assert "chain kdsl cpu:" in proc.stdout and "us/step" in proc.stdout
    assert "Ordered by: internal time" in proc.stdout
    assert "Ordered by: cumulative time" in proc.stdout
    assert "launch" in proc.stdout  # kdsl's launch path shows in the profile


def test_profile_scene_refuses_an_unknown_scene():
    proc = _profile("no_such_scene")
    assert proc.returncode == 2 and "invalid choice" in proc.stderr
