"""Install hints agree with the README, which says what a fresh machine needs (issue 13)."""

import re
import sys
from pathlib import Path

import pytest

from kdsl.backends.cuda import nvrtc
from kdsl.errors import KdslError

README = (Path(__file__).resolve().parents[2] / "README.md").read_text()


def test_readme_states_python_version_and_virtual_environment():
    assert "Python 3.11 or newer" in README
    assert "virtual" in README and "python3 -m venv" in README


def test_cuda_install_hint_matches_readme():
    extras = re.findall(r'"\.\[(cuda\d+)\]"', nvrtc.INSTALL_HINT)
    assert extras == ["cuda13", "cuda12"]
    for extra in extras:
        assert f'".[{extra}]"' in README


def test_missing_cupy_names_the_install_hint(monkeypatch):
    # Compiling needs NVRTC (its version alone may come from the kernel cache).
    monkeypatch.setitem(sys.modules, "cupy_backends.cuda.libs", None)  # import fails
    with pytest.raises(KdslError, match=re.escape(nvrtc.INSTALL_HINT)):
        nvrtc.compile_source("__global__ void k() {}", "sm_90")
