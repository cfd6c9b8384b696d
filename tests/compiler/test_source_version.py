"""``backends.base.source_version``: a backend's code digest, kept as a fact by ``stat``.

The digest is always of the files' contents (equal sources, equal keys, on any machine);
a warm process finds it by the files' paths, sizes and times instead of reading them,
except for files modified within ``SETTLED_S`` seconds, which are read every time.
"""

from __future__ import annotations

import hashlib
import os
import time
from pathlib import Path

import pytest

from kdsl.backends.base import SETTLED_S, source_version
from kdsl.compiler import cache


@pytest.fixture(autouse=True)
def _private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("KDSL_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("KDSL_CACHE", raising=False)
    cache.MEMORY.clear()


def _sources(root: Path, texts: dict[str, str], age_s: float) -> list[Path]:
    root.mkdir(exist_ok=True)
    then = time.time_ns() - int(age_s * 1e9)
    paths = []
    for name, text in texts.items():
        p = root / name
        p.write_text(text)
        os.utime(p, ns=(then, then))
        paths.append(p)
    return paths


def _by_contents(version: str, paths: list[Path]) -> str:
    h = hashlib.sha256(version.encode())
    for p in sorted(paths):
        h.update(p.name.encode() + b"\0" + p.read_bytes())
    return f"{version}+{h.hexdigest()[:16]}"


def test_the_digest_is_of_the_contents_and_kept_for_settled_files(tmp_path):
    paths = _sources(tmp_path / "b", {"a.py": "A = 1\n", "b.py": "B = 2\n"}, age_s=60)
    builds = cache.FACT_STATS.builds
    first = source_version("3", paths)
    assert first == _by_contents("3", paths)
    assert cache.FACT_STATS.builds == builds + 1  # learnt once, kept
    cache.MEMORY.clear()  # a new process: the fact comes from the disk
    hits = cache.FACT_STATS.disk_hits
    assert source_version("3", paths) == first
    assert cache.FACT_STATS.disk_hits == hits + 1
    assert source_version("4", paths) == _by_contents("4", paths)  # the version is in it


def test_an_edit_changes_the_digest(tmp_path):
    paths = _sources(tmp_path / "b", {"a.py": "A = 1\n", "b.py": "B = 2\n"}, age_s=60)
    first = source_version("3", paths)
    (tmp_path / "b" / "b.py").write_text("B = 3\n")  # the same size, a new time
    edited = source_version("3", paths)
    assert edited == _by_contents("3", paths) != first
    # Settled again (an older time than the first record, even): still the new contents.
    _sources(tmp_path / "b", {"b.py": "B = 3\n"}, age_s=30)
    assert source_version("3", paths) == edited


def test_files_modified_just_now_are_read_every_time(tmp_path):
    paths = _sources(tmp_path / "b", {"a.py": "A = 1\n"}, age_s=SETTLED_S / 4)
    builds = cache.FACT_STATS.builds
    assert source_version("3", paths) == _by_contents("3", paths)
    assert cache.FACT_STATS.builds == builds  # nothing kept: a same-tick edit could follow
