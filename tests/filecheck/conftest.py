"""Collects ``*.kir`` FileCheck tests: each ``// RUN:`` line is one pytest item.

A RUN line reads ``// RUN: kdsl opt %s -p PIPELINE [--print-after-all] [--debuginfo]
| filecheck %s [FLAGS]``. Instead of a shell, the item calls
``kdsl.tools.opt.run_opt`` and pipes its output to the ``filecheck`` package. Every
file also gets a ``roundtrip`` item: print(parse(text)) must parse and print back
identically (xDSL's ``XDSL_ROUNDTRIP``), with and without locations.
"""

from __future__ import annotations

import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from kdsl.ir import parse_module, print_module
from kdsl.tools.opt import run_opt

_OPT_FLAGS = {"--print-after-all": "print_after_all", "--debuginfo": "debuginfo"}


def pytest_collect_file(parent, file_path: Path):
    if file_path.suffix == ".kir":
        return KirFile.from_parent(parent, path=file_path)
    return None


class KirFile(pytest.File):
    def collect(self):
        lines = self.path.read_text().splitlines()
        runs = [ln.split("RUN:", 1)[1].strip() for ln in lines if ln.lstrip().startswith("// RUN:")]
        if not runs:
            raise pytest.UsageError(f"{self.path} has no // RUN: line")
        for i, run in enumerate(runs):
            yield RunItem.from_parent(self, name=f"run{i}", run=run)
        yield RoundTripItem.from_parent(self, name="roundtrip")


def parse_run_line(run: str) -> tuple[str, dict[str, bool], list[str]]:
    """(pipeline, run_opt flags, filecheck args) of one RUN line."""
    opt_part, _, check_part = run.partition("|")
    words = shlex.split(opt_part)
    if words[:2] == ["kdsl", "opt"]:
        words = words[2:]
    elif words[:1] == ["kdsl-opt"]:
        words = words[1:]
    else:
        raise ValueError(f"RUN line must start with 'kdsl opt': {run}")
    pipeline, flags = "", {}
    it = iter(words)
    for w in it:
        if w == "-p":
            pipeline = next(it)
        elif w in _OPT_FLAGS:
            flags[_OPT_FLAGS[w]] = True
        elif w != "%s":
            raise ValueError(f"unknown kdsl opt argument {w!r} in: {run}")
    check = shlex.split(check_part)
    if check[:1] != ["filecheck"]:
        raise ValueError(f"RUN line must pipe into filecheck: {run}")
    return pipeline, flags, [a for a in check[1:] if a != "%s"]


class RunItem(pytest.Item):
    def __init__(self, *, run: str, **kwargs):
        super().__init__(**kwargs)
        self.run = run

    def runtest(self):
        pipeline, flags, check_args = parse_run_line(self.run)
        text = self.path.read_text()
        output = run_opt(text, pipeline, file=self.path.name, **flags)
        proc = subprocess.run(
            [sys.executable, "-m", "filecheck", *check_args, str(self.path)],
            input=output, capture_output=True, text=True,
        )  # fmt: skip
        if proc.returncode != 0:
            raise FileCheckFailure(f"{proc.stdout}{proc.stderr}\n--- kdsl opt output ---\n{output}")

    def repr_failure(self, excinfo):
        if isinstance(excinfo.value, FileCheckFailure):
            return f"{self.run}\n{excinfo.value}"
        return super().repr_failure(excinfo)

    def reportinfo(self):
        return self.path, 0, f"{self.path.name}: {self.run}"


class RoundTripItem(pytest.Item):
    def runtest(self):
        text = self.path.read_text()
        for debuginfo in (False, True):
            once = print_module(parse_module(text, file=self.path.name), debuginfo=debuginfo)
            twice = print_module(parse_module(once, file=self.path.name), debuginfo=debuginfo)
            assert once == twice

    def reportinfo(self):
        return self.path, 0, f"{self.path.name}: roundtrip"


class FileCheckFailure(Exception):
    """filecheck rejected the output of kdsl opt."""
