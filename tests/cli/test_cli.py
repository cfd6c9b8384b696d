"""The ``kdsl`` command line: every command, and clean errors (exit 2, no traceback)."""

import io
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from kdsl.cli import _Tally, main, split_target
from kdsl.ir import parse_module

ROOT = Path(__file__).resolve().parents[2]
SAXPY = str(ROOT / "examples" / "saxpy.py")


def run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def bad_kernel(tmp_path: Path) -> str:
    path = tmp_path / "bad.py"
    path.write_text(
        textwrap.dedent("""\
        import kdsl as wp

        @wp.kernel
        def bad(x: wp.array(dtype=float)):
            i = wp.tid()
            x[i] = [1.0, 2.0]
        """)
    )
    return str(path)


def test_ir_default_stage_is_optimized(capsys):
    code, out, err = run(capsys, "ir", f"{SAXPY}:saxpy")
    assert code == 0, err
    assert out.startswith("func.func @saxpy")
    assert "kd.store" in out and "loc(" not in out
    parse_module(out)  # what kdsl ir prints, kdsl opt can read


def test_ir_stage_kir_with_debuginfo(capsys):
    code, out, _ = run(capsys, "ir", f"{SAXPY}:saxpy", "--stage", "kir", "--debuginfo")
    assert code == 0
    assert 'loc("' in out and "saxpy.py" in out


def test_ir_all_kernels_when_none_named(capsys):
    code, out, _ = run(capsys, "ir", SAXPY)
    assert code == 0
    assert "// kernel saxpy" in out and "// kernel integrate" in out
    assert out.count("func.func @") == 2


def test_ir_print_after_all_and_time_passes(capsys):
    code, out, _ = run(capsys, "ir", f"{SAXPY}:saxpy", "--print-after-all", "--time-passes")
    assert code == 0
    assert "IR Dump After inline" in out and "IR Dump After dce" in out
    assert "pass execution timing" in out


def test_ir_custom_pipeline_and_features(capsys):
    code, out, _ = run(capsys, "ir", f"{SAXPY}:saxpy", "--pipeline", "dce", "--print-after-all")
    assert code == 0
    assert "IR Dump After dce" in out and "IR Dump After inline" not in out
    code, out, _ = run(capsys, "ir", f"{SAXPY}:integrate", "--features")
    assert code == 0 and out.startswith("ops: ") and "kd.store" in out and "vec" in out


def test_ir_backend_stage(capsys):
    code, out, _ = run(capsys, "ir", f"{SAXPY}:saxpy", "--backend", "interp", "--stage", "kir-opt")
    assert code == 0 and out.startswith("func.func @saxpy")


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["ir", "no/such/file.py"], "no such file"),
        (["ir", f"{SAXPY}:nokernel"], "no kernel named 'nokernel'"),
        (["ir", SAXPY, "--pipeline", "inline,bogus"], "unknown pass 'bogus'"),
        (["ir", SAXPY, "--stage", "zzz"], "no stage 'zzz'"),
        (["ir", SAXPY, "--backend", "nope"], "no kdsl backend is named 'nope'"),
        (["opt", "no/such.kir", "-p", "dce"], "no such file"),
        (["pipeline", "nope"], "no kdsl backend is named 'nope'"),
    ],
)
def test_bad_input_exits_2_without_traceback(capsys, argv, message):
    code, out, err = run(capsys, *argv)
    assert code == 2
    assert message in err and "Traceback" not in err
    assert out == ""


def test_kernel_error_points_at_source(capsys, bad_kernel):
    code, _, err = run(capsys, "ir", bad_kernel)
    assert code == 2
    assert f'File "{bad_kernel}", line 6' in err
    assert "x[i] = [1.0, 2.0]" in err and "^^^" in err
    assert "Traceback" not in err


def test_python_syntax_error_in_file(capsys, tmp_path):
    path = tmp_path / "syn.py"
    path.write_text("def f(:\n    pass\n")
    code, _, err = run(capsys, "ir", str(path))
    assert code == 2
    assert "SyntaxError" in err and "line 1" in err and "^" in err


def test_opt_file_and_stdin(capsys, monkeypatch, tmp_path):
    code, kir, _ = run(capsys, "ir", f"{SAXPY}:saxpy", "--stage", "kir")
    path = tmp_path / "saxpy.kir"
    path.write_text(kir)
    code, out, err = run(capsys, "opt", str(path), "-p", "fold,cse,dce")
    assert code == 0, err
    assert parse_module(out) is not None
    monkeypatch.setattr(sys, "stdin", io.StringIO(kir))
    code, out2, _ = run(capsys, "opt", "-", "-p", "fold,cse,dce", "--time-passes")
    assert code == 0 and "pass execution timing" in out2 and out in out2


def test_opt_parse_error_has_location(capsys, tmp_path):
    path = tmp_path / "bad.kir"
    path.write_text('func.func @f() -> () {kind = "kernel"} {\n  %0 = arith.add %x, %x : f32\n'
                    "  func.return\n}\n")  # fmt: skip
    code, _, err = run(capsys, "opt", str(path), "-p", "dce")
    assert code == 2
    assert "undefined value %x" in err and f'File "{path}", line 2' in err


def test_backends_and_pipeline(capsys):
    from kdsl.backends.registry import get_backend

    code, out, _ = run(capsys, "backends")
    assert code == 0
    assert out.startswith("interp ") or "\ninterp " in out
    assert "capabilities:" in out and "devices:" in out
    code, out, _ = run(capsys, "pipeline", "interp")
    assert code == 0 and out.strip() == get_backend("interp").pipeline


def test_split_target():
    assert split_target("a/b.py:k") == ("a/b.py", "k")
    assert split_target("a/b.py") == ("a/b.py", None)
    assert split_target("C:/x/b.py") == ("C:/x/b.py", None)


def test_tally_summary_line():
    t = _Tally()
    assert t.summary() == "0 passed, 0 failed"
    t.passed, t.failed, t.skipped = 3, 1, 2
    assert t.summary() == "3 passed, 1 failed, 2 skipped"


def _kdsl(*argv: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "kdsl", *argv], capture_output=True, text=True,
                          cwd=ROOT, env={**os.environ, **(env or {})}, timeout=120)  # fmt: skip


def test_conformance_command_counts():
    proc = _kdsl("conformance", "--backend", "interp", "-k", "tid_1d or tid_2d")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stdout.splitlines()[-1] == "2 passed, 0 failed"


def test_traceback_env_shows_traceback():
    proc = _kdsl("ir", "no/such/file.py", env={"KDSL_TRACEBACK": "full"})
    assert proc.returncode != 0 and "Traceback" in proc.stderr
    proc = _kdsl("ir", "no/such/file.py")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr


def test_conformance_failure_sets_exit_status(capsys):
    import dataclasses

    from kdsl.testing.cases import memory

    i = next(k for k, c in enumerate(memory.CASES) if c.name == "tid_1d")
    right = memory.CASES[i]
    memory.CASES[i] = dataclasses.replace(right, reference=lambda ins: {"out": np.arange(37)})
    try:
        code, out, _ = run(capsys, "conformance", "--backend", "interp", "-k", "tid_1d or tid_2d")
    finally:
        memory.CASES[i] = right
    assert code == 1
    assert out.splitlines()[-1] == "1 passed, 1 failed"


def test_closed_pipe_is_not_an_internal_error(tmp_path: Path):
    # `kdsl ir file.py | head -1`: the reader exits early; kdsl must exit quietly.
    many = tmp_path / "many.py"
    kernel = "@wp.kernel\ndef k{n}(a: wp.array(dtype=float)):\n    a[wp.tid()] = {n}.0\n\n"
    many.write_text("import kdsl as wp\n\n" + "".join(kernel.format(n=n) for n in range(400)))
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(  # far more output than a pipe buffers
        [sys.executable, "-m", "kdsl.cli", "ir", str(many), "--stage", "kir"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, cwd=tmp_path,
    )  # fmt: skip
    proc.stdout.readline()
    proc.stdout.close()  # the pipe's reader goes away with output still to come
    err = proc.stderr.read().decode()
    proc.wait(timeout=60)
    assert "internal error" not in err and "Traceback" not in err
    assert proc.returncode == 0
