"""The pass manager's verification policy and its lazy crash-reproducer snapshots."""

from __future__ import annotations

import gc
import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import pytest

from kdsl import config
from kdsl.errors import KdslError, KdslVerifyError
from kdsl.ir import Module, Operation, parse_module, print_module, verify_module
from kdsl.ir.core import OpResult, Value
from kdsl.passes import ModulePass, PassCrashError, PassManager, optimize, parse_pipeline
from kdsl.passes.manager import clone_module
from kdsl.testing.cases.programs import make_programs
from tests.passes.broken_passes import SRC, BreakIRPass, CrashPass


@dataclass(frozen=True)
class MutateThenCrashPass(ModulePass):
    """Changes ops, an attribute in place and a value's name, then raises."""

    name: ClassVar[str] = "mutate-then-crash"

    def apply(self, module: Module) -> bool:
        func = module.funcs[0]
        func.attrs["res_types"].append(func.attrs["res_types"][0])
        body = func.regions[0].block
        body.ops[0].attrs["value"] = 7.0
        body.ops[0].results[0].name_hint = "renamed"
        body.args[0].replace_all_uses_with(body.ops[1].results[0])
        body.detach(body.ops[-1])
        raise RuntimeError("half done")


def _verify_after_every_pass(monkeypatch, policy: str, mode: str = "release") -> None:
    monkeypatch.setattr(config, "verify_passes", policy)
    monkeypatch.setattr(config, "mode", mode)


def test_the_test_suite_verifies_after_every_pass():
    assert config.verify_passes == "each"
    assert os.environ["KDSL_VERIFY_PASSES"] == "each"
    pm = PassManager("fold,dce")
    assert pm.verify and pm.verify_each


@pytest.mark.parametrize(
    "policy, mode, each",
    [
        ("auto", "release", False),
        ("auto", "debug", True),
        ("each", "release", True),
        ("end", "debug", False),
    ],
)
def test_policy_follows_the_config(monkeypatch, policy, mode, each):
    _verify_after_every_pass(monkeypatch, policy, mode)
    assert config.verify_each_pass() is each
    pm = PassManager("fold")
    assert pm.verify and pm.verify_each is each
    # Explicit arguments win: True after every pass, False never.
    assert PassManager("fold", verify_each=True).verify_each
    off = PassManager("fold", verify_each=False)
    assert not off.verify and not off.verify_each


def test_bad_policy_is_refused(monkeypatch):
    monkeypatch.setattr(config, "verify_passes", "sometimes")
    with pytest.raises(KdslError, match=r"verify_passes .*'sometimes'"):
        PassManager("fold")


@pytest.mark.parametrize("env, want", [(None, "auto"), ("end", "end"), ("", "auto")])
def test_the_environment_variable_sets_the_option(env, want):
    environ = {k: v for k, v in os.environ.items() if k != "KDSL_VERIFY_PASSES"}
    if env is not None:
        environ["KDSL_VERIFY_PASSES"] = env
    code = "import kdsl.config as c; print(c.verify_passes)"
    out = subprocess.run([sys.executable, "-c", code], env=environ, capture_output=True,
                         text=True, check=True)  # fmt: skip
    assert out.stdout.strip() == want


def test_release_verifies_once_at_the_end(monkeypatch):
    _verify_after_every_pass(monkeypatch, "auto")
    calls = []
    monkeypatch.setattr("kdsl.passes.manager.verify_module",
                        lambda m: calls.append(m) or verify_module(m))  # fmt: skip
    module = parse_module(SRC)
    PassManager("fold,canonicalize,cse,dce").run(module)
    assert calls == [module]


def _messages(error: BaseException) -> tuple[str, Path]:
    """The error's text without the reproducer path, and the reproducer's path."""
    text = str(error)
    path = re.search(r"reproducer: (\S+\.kir)", text).group(1)
    return text.replace(path, "PATH"), Path(path)


@pytest.mark.parametrize("after", [[], parse_pipeline("dce"), [CrashPass()]])
def test_end_verification_raises_what_verify_each_would(monkeypatch, tmp_path, after):
    """The pass that broke the IR is named even if later passes ran (or crashed) on it."""
    passes = [*parse_pipeline("fold"), BreakIRPass(), *after]
    results = {}
    for policy in ("each", "end"):
        _verify_after_every_pass(monkeypatch, policy)
        out = tmp_path / policy
        out.mkdir()
        with pytest.raises(KdslVerifyError, match="after pass break-ir") as info:
            PassManager(passes, reproducer_dir=str(out)).run(parse_module(SRC))
        text, path = _messages(info.value)
        assert list(out.iterdir()) == [path]
        results[policy] = (text, path.read_text())
    assert results["end"] == results["each"]
    repro = results["end"][1]
    assert "// pipeline: " + ",".join(p.spec() for p in passes) in repro
    assert "arith.mul" not in repro  # the IR after fold, before break-ir
    verify_module(parse_module(repro))


def test_crash_reproducer_is_the_same_under_every_policy(monkeypatch, tmp_path):
    texts = set()
    for policy in ("each", "end"):
        _verify_after_every_pass(monkeypatch, policy)
        out = tmp_path / policy
        out.mkdir()
        pm = PassManager([*parse_pipeline("fold"), CrashPass()], reproducer_dir=str(out))
        with pytest.raises(PassCrashError, match="pass crash crashed: ZeroDivisionError"):
            pm.run(parse_module(SRC))
        (path,) = out.iterdir()
        texts.add(path.read_text())
    assert len(texts) == 1


def test_reproducer_holds_the_ir_from_before_a_pass_that_changed_it_and_crashed(tmp_path):
    module = parse_module(SRC)
    want = print_module(module, debuginfo=True)
    pm = PassManager([MutateThenCrashPass()], reproducer_dir=str(tmp_path))
    with pytest.raises(PassCrashError, match="half done"):
        pm.run(module)
    assert print_module(module, debuginfo=True) != want  # the pass did change it
    (path,) = tmp_path.iterdir()
    text = path.read_text()
    assert text.endswith(want)
    assert "// RUN: kdsl opt %s -p mutate-then-crash" in text


@dataclass(frozen=True)
class BreakOnceIRPass(ModulePass):
    """Breaks the IR on its first run only (a pass that does not repeat itself)."""

    name: ClassVar[str] = "break-once"
    runs: ClassVar[list[int]] = []

    def apply(self, module: Module) -> bool:
        self.runs.append(1)
        return BreakIRPass().apply(module) if len(self.runs) == 1 else False


def test_end_failure_that_does_not_repeat_blames_the_pipeline(monkeypatch, tmp_path):
    _verify_after_every_pass(monkeypatch, "end")
    BreakOnceIRPass.runs.clear()
    module = parse_module(SRC)
    want = print_module(module, debuginfo=True)
    pm = PassManager([*parse_pipeline("fold"), BreakOnceIRPass()], reproducer_dir=str(tmp_path))
    with pytest.raises(KdslVerifyError, match="after pipeline fold,break-once; reproducer"):
        pm.run(module)
    (path,) = tmp_path.iterdir()
    text = path.read_text()
    assert "// RUN: kdsl opt %s -p fold,break-once" in text
    assert text.endswith(want)


def test_the_collector_is_paused_during_a_run_and_restored():
    seen = []

    @dataclass(frozen=True)
    class Probe(ModulePass):
        name: ClassVar[str] = "probe"

        def apply(self, module: Module) -> bool:
            seen.append(gc.isenabled())
            return False

    assert gc.isenabled()
    PassManager([Probe()]).run(parse_module(SRC))
    assert seen == [False] and gc.isenabled()
    with pytest.raises(PassCrashError):
        PassManager([CrashPass()]).run(parse_module(SRC))
    assert gc.isenabled()
    gc.disable()
    try:
        PassManager([Probe()]).run(parse_module(SRC))
        assert not gc.isenabled()
    finally:
        gc.enable()


# --- clone_module -----------------------------------------------------------------


def _modules() -> list[Module]:
    out = [parse_module(SRC)]
    for kernel in make_programs().values():
        out.append(kernel.build_module())
    return out


def _objects(module: Module) -> set[int]:
    ids = {id(module.body)}
    for op in module.walk():
        ids |= {id(op), id(op.attrs), *map(id, op.results), *(id(r) for r in op.regions)}
        for region in op.regions:
            ids |= {id(region.block), *map(id, region.block.args)}
    return ids


@pytest.mark.parametrize("index", range(6))
def test_clone_prints_the_same_and_shares_nothing_mutable(index):
    module = _modules()[index]
    text = print_module(module, debuginfo=True)
    copy = clone_module(module)
    assert print_module(copy, debuginfo=True) == text
    verify_module(copy)
    assert not _objects(module) & _objects(copy)
    optimize(copy)  # changing the copy leaves the original as it was
    assert print_module(module, debuginfo=True) == text
    verify_module(module)


def test_clone_copies_invalid_ir_without_touching_the_original():
    module = parse_module(SRC)
    BreakIRPass().apply(module)
    uses = {id(v): list(v.uses) for op in module.walk() for v in op.results}
    copy = clone_module(module)
    assert print_module(copy, debuginfo=True) == print_module(module, debuginfo=True)
    assert {id(v): list(v.uses) for op in module.walk() for v in op.results} == uses
    ret = copy.funcs[0].regions[0].block.ops[0]
    (d,) = ret.operands
    assert (ret, 0) in d.uses and d.op.parent is copy.funcs[0].regions[0].block


def test_clone_knows_every_field_of_the_ir_objects():
    """clone_module sets the fields of ops and results one by one: a new one goes there too."""
    assert Operation.__slots__ == (
        "opdef", "operands", "results", "attrs", "regions", "loc", "parent"
    )  # fmt: skip
    assert Value.__slots__ == ("type", "uses", "name_hint")
    assert OpResult.__slots__ == ("op", "index")
