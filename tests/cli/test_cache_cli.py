"""``kdsl cache info`` and ``kdsl cache clear``, always on a private cache directory."""

from __future__ import annotations

import os
import uuid
from pathlib import Path

import pytest

from kdsl.cli import main
from kdsl.compiler import cache
from kdsl.compiler.cache import DiskCache


@pytest.fixture(autouse=True)
def cache_dir(tmp_path, monkeypatch) -> Path:
    """A fresh cache directory for each test (never the user's own)."""
    directory = tmp_path / "kdsl-cache"
    monkeypatch.setenv("KDSL_CACHE_DIR", str(directory))
    monkeypatch.delenv("KDSL_CACHE", raising=False)
    return directory


def run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def fill(directory: Path, sizes: list[int]) -> int:
    """Store one entry per size; gives their total size on disk."""
    directory.mkdir(mode=0o700, exist_ok=True)
    disk = DiskCache(directory)
    for n in sizes:
        disk.store(cache.kernel_key(uuid.uuid4().hex, "t", "1", {}, "x"), b"\0" * n)
    return sum(p.stat().st_size for p in disk.entries())


def test_info_on_a_missing_directory(capsys, cache_dir):
    code, out, _ = run(capsys, "cache", "info")
    assert code == 0
    assert f"directory: {cache_dir}" in out and "entries:   0" in out
    assert not cache_dir.exists()  # info never creates it


def test_info_counts_entries_and_bytes(capsys, cache_dir):
    total = fill(cache_dir, [10, 200, 3000])
    code, out, _ = run(capsys, "cache", "info")
    assert code == 0
    assert "entries:   3" in out and f"size:      {total} bytes" in out
    assert "disabled" not in out


def test_clear_removes_entries_and_temporaries_only(capsys, cache_dir):
    total = fill(cache_dir, [10, 20])
    (cache_dir / ".abc.123.tmp").write_bytes(b"half written")
    (cache_dir / "notes.txt").write_text("not the cache's")
    code, out, _ = run(capsys, "cache", "clear")
    assert code == 0 and f"removed 2 entries ({total} bytes)" in out
    assert [p.name for p in cache_dir.iterdir()] == ["notes.txt"]
    _, out, _ = run(capsys, "cache", "info")
    assert "entries:   0" in out


@pytest.mark.skipif(os.name != "posix", reason="POSIX permissions")
def test_clear_refuses_an_unsafe_directory(capsys, cache_dir):
    fill(cache_dir, [10])
    cache_dir.chmod(0o777)
    code, _, err = run(capsys, "cache", "clear")
    assert code == 2 and "writable by group or others" in err
    assert len(DiskCache(cache_dir).entries()) == 1
    _, out, _ = run(capsys, "cache", "info")
    assert "disabled:" in out


def test_info_says_when_the_cache_is_off(capsys, monkeypatch):
    monkeypatch.setenv("KDSL_CACHE", "off")
    code, out, _ = run(capsys, "cache", "info")
    assert code == 0 and "disabled:  KDSL_CACHE is off" in out


def test_unknown_action_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as e:
        main(["cache", "purge"])
    assert e.value.code == 2
