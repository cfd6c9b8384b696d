"""The differential fuzzer's bounded CI budget, and tests of its oracles.

The budget is derandomized (the same programs every run): the long, random search is
``python -m kdsl.testing.fuzz --minutes N`` (docs/testing.md, "Differential fuzzing").
"""

import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings

from kdsl.errors import KdslError, KdslTypeError
from kdsl.testing.fuzz import (
    KNOWN_ISSUES,
    FuzzFailure,
    check_invalid,
    check_program,
    invalid_programs,
    is_internal,
    programs,
)
from kdsl.testing.fuzz.check import compare_outputs, load, ulp_distance
from kdsl.testing.fuzz.program import Assign, Line
from kdsl.testing.fuzz.run import known_issue


def budget(examples: int) -> settings:
    """A fixed, derandomized number of examples (the same programs every run)."""
    return settings(
        max_examples=examples,
        derandomize=True,
        database=None,
        deadline=None,
        suppress_health_check=list(HealthCheck),
    )


def _check(program):
    """Check a program; a known open issue (KNOWN_ISSUES) does not fail CI."""
    try:
        check_program(program)
    except FuzzFailure as failure:
        if known_issue(failure, KNOWN_ISSUES) is None:
            raise


@budget(80)
@given(programs(max_depth=2, max_stmts=4))
def test_valid_programs_compile_roundtrip_agree_and_differentiate(program):
    _check(program)


@budget(50)
@given(invalid_programs())
def test_invalid_programs_give_located_errors(program):
    _check(program)


# --------------------------------------------------------------------------- the oracles fail


@budget(1)
@given(programs(max_depth=0, max_stmts=1, differentiable=False))
def test_an_invalid_program_that_compiles_is_reported(program):
    # A program labelled invalid but with nothing broken must fail check_invalid.
    bad = replace(
        program,
        invalid="nothing broken",
        body=(Line("pass  # <- error here"),),
        result_f="xs[i]",
        result_i="i",
    )
    with pytest.raises(FuzzFailure, match="invalid/accepted"):
        check_invalid(bad)


@budget(1)
@given(programs(max_depth=0, max_stmts=1, differentiable=False))
def test_a_valid_program_kdsl_rejects_is_reported(program):
    bad = replace(
        program, body=(Assign("v", "xs[i] + wp.int32(1)"),), result_f="xs[i]", result_i="i"
    )
    with pytest.raises(FuzzFailure, match="rejected-valid"):
        check_program(bad)


def test_backend_mismatch_beyond_the_ulp_bound_is_reported():
    ref = [np.array([1.0, 2.0], np.float32), np.array([3, 4], np.int32)]
    near = [np.nextafter(ref[0], np.float32(9)), ref[1].copy()]
    compare_outputs(ref, near, ("interp", "cpu"))  # 1 ulp: within the bound
    far = [ref[0] + np.float32(0.01), ref[1].copy()]
    with pytest.raises(AssertionError, match=r"out\[0\]: interp gives 1.0, cpu gives 1.00999"):
        compare_outputs(ref, far, ("interp", "cpu"))
    with pytest.raises(AssertionError, match=r"iout\[1\]"):
        compare_outputs(ref, [ref[0], np.array([3, 5], np.int32)], ("interp", "cpu"))


def test_ulp_distance_treats_nans_and_infinities():
    a = np.array([np.nan, np.inf, 1.0, np.nan], np.float32)
    b = np.array([np.nan, np.inf, 1.0, 0.0], np.float32)
    assert ulp_distance(a, b).tolist() == [0.0, 0.0, 0.0, np.inf]


def test_known_issues_are_matched_by_their_text():
    failure = FuzzFailure(
        "gradient-cpu/internal", "TypeError: cannot add values of type struct<P>", ""
    )
    known = {r"cannot add values of type struct": "struct adjoint (issue 13)"}
    assert known_issue(failure, known) == "struct adjoint (issue 13)"
    assert known_issue(failure, {r"loop variable": "other"}) is None
    assert (
        failure.signature()
        == "gradient-cpu/internal: TypeError: cannot add values of type struct<P>"
    )


def test_internal_errors_are_told_apart_from_user_errors():
    assert is_internal(TypeError("cannot add values of type struct<Params>"))
    assert is_internal(KdslError("internal: loop variable $iv lost"))
    assert is_internal(KdslError("internal error in pass fold (this is a kdsl bug)"))
    assert not is_internal(KdslTypeError("cannot add f32 and i32"))


@budget(1)
@given(program=programs(max_depth=1, max_stmts=2, differentiable=False))
def test_a_program_prints_as_a_runnable_python_file(program, tmp_path_factory):
    path = tmp_path_factory.mktemp("fuzz") / "repro.py"
    path.write_text(program.source())
    done = subprocess.run([sys.executable, str(path)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("interp [") and "\ncpu [" in done.stdout
    # and it imports as a module with the kernel and its runner
    module = load(program.source())
    assert module.run("interp")[4].shape == (6,)


def test_the_command_line_prints_a_summary(tmp_path):
    cmd = [sys.executable, "-m", "kdsl.testing.fuzz", "--minutes", "0.01",
           "--out", str(tmp_path / "found"), "--seed", "3"]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert "kdsl fuzz: " in done.stdout and "new failures: " in done.stdout, done.stderr
    assert done.returncode in (0, 1)
