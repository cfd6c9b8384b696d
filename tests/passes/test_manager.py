"""The pass manager: registry, pipeline text, verification, dumps, timing, reproducers."""

from __future__ import annotations

import io
import re
from pathlib import Path

import pytest

from kdsl.errors import KdslVerifyError
from kdsl.ir import parse_module, print_module
from kdsl.passes import (
    DEFAULT_PIPELINE,
    PassCrashError,
    PassManager,
    get_all_passes,
    optimize,
    parse_pipeline,
    pass_names,
    pipeline_str,
    run_fixpoint,
    run_pipeline,
)
from tests.passes.broken_passes import SRC, BreakIRPass, CrashPass


def test_registry_matches_file_names():
    passes = get_all_passes()
    assert set(passes) == set(pass_names())
    assert {"inline", "fold", "canonicalize", "cse", "dce", "features"} <= set(passes)
    for name, cls in passes.items():
        assert cls.name == name
        assert cls.__module__ == "kdsl.passes." + name.replace("-", "_")


def test_parse_pipeline_with_options_round_trips():
    passes = parse_pipeline("inline, fold{max_iters=3} ,cse,canonicalize{speculate_limit=0}")
    assert [p.name for p in passes] == ["inline", "fold", "cse", "canonicalize"]
    assert passes[1].max_iters == 3
    assert pipeline_str(passes) == "inline,fold{max_iters=3},cse,canonicalize{speculate_limit=0}"
    assert parse_pipeline(pipeline_str(passes)) == passes
    assert parse_pipeline(DEFAULT_PIPELINE)
    assert parse_pipeline("inline{drop_unused=false}")[0].drop_unused is False


@pytest.mark.parametrize(
    "text, message",
    [
        ("nosuchpass", "unknown pass 'nosuchpass'"),
        ("fold{bogus=1}", "no option 'bogus'"),
        ("fold{max_iters=many}", "expects a int"),
        ("fold{max_iters}", "key=value"),
        ("fold,,dce", "bad pass pipeline"),
    ],
)
def test_parse_pipeline_errors(text, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        parse_pipeline(text)


def test_verify_each_names_the_pass_and_writes_a_reproducer(tmp_path):
    module = parse_module(SRC)
    pm = PassManager([BreakIRPass()], reproducer_dir=str(tmp_path))
    with pytest.raises(KdslVerifyError, match="after pass break-ir") as info:
        pm.run(module)
    path = re.search(r"reproducer: (\S+\.kir)", str(info.value)).group(1)
    repro = Path(path).read_text()
    assert "// pipeline: break-ir" in repro
    # The reproducer holds the IR from before the failing pass, and parses.
    assert print_module(parse_module(repro)) == SRC


def test_verify_each_can_be_turned_off():
    module = parse_module(SRC)
    PassManager([BreakIRPass()], verify_each=False).run(module)


def test_crash_writes_reproducer(tmp_path):
    module = parse_module(SRC)
    pm = PassManager([*parse_pipeline("fold"), CrashPass()], reproducer_dir=str(tmp_path))
    with pytest.raises(PassCrashError, match="pass crash crashed: ZeroDivisionError: boom") as e:
        pm.run(module)
    (path,) = tmp_path.iterdir()
    assert str(path) in str(e.value)
    text = path.read_text()
    assert "// pipeline: fold,crash" in text
    assert "arith.mul" not in text  # written after fold ran, before the crash


def test_print_before_after_and_timings():
    out = io.StringIO()
    pm = PassManager("fold,dce", print_before=["dce"], print_after=["fold"], out=out,
                     time_passes=True)  # fmt: skip
    assert pm.run(parse_module(SRC)) is True
    text = out.getvalue()
    assert text.index("// -----// IR Dump After fold //----- //") < text.index(
        "// -----// IR Dump Before dce //----- //"
    )
    assert "IR Dump After dce" not in text
    assert [t.name for t in pm.timings] == ["fold", "dce"]
    assert all(t.seconds >= 0 and t.changed for t in pm.timings)
    assert "Total" in text and "fold" in pm.timing_report()


def test_print_after_all():
    out = io.StringIO()
    PassManager("fold,cse", print_after_all=True, out=out).run(parse_module(SRC))
    assert out.getvalue().count("IR Dump After") == 2


def test_unchanged_module_reports_no_change():
    module = parse_module('func.func @k() -> () {kind = "kernel"} {\n  func.return\n}\n')
    assert PassManager(DEFAULT_PIPELINE).run(module) is False


KSRC = (
    SRC
    + """
func.func @k(%arr: array<f32, 1>) -> () {kind = "kernel"} {
  %i = kd.tid {dim = 0, ndim = 1} : i32
  %x = kd.load %arr, %i : f32
  %y = func.call %x {callee = "f"} : f32
  kd.store %y, %arr, %i
  func.return
}
"""
)


def test_run_pipeline_optimize_and_fixpoint():
    module = run_pipeline(parse_module(KSRC))
    assert "func.func @f" not in print_module(module)
    assert "arith.mul" not in print_module(module)
    assert "value = 6.0" in print_module(module)
    m2 = optimize(parse_module(KSRC))
    assert print_module(m2) == print_module(module)
    m3 = parse_module(SRC)
    assert run_fixpoint(m3, "fold,dce") is True
    assert run_fixpoint(m3, "fold,dce") is False
