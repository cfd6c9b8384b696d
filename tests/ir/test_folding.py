"""Folding goes through the op catalog: ``OpDef.folder`` for IR constants,
``fold_literal`` for a kernel's untyped Python literals."""

import math

import pytest

from kdsl.ir import CATALOG, parse_module, print_module
from kdsl.ir.catalog import PURE, fold_literal
from kdsl.passes import run_pipeline

SRC = """\
func.func @k(%a: array<f32, 1>) -> () {kind = "kernel"} {
  %0 = arith.constant {value = 7.0} : f32
  %1 = arith.constant {value = 2.0} : f32
  %2 = arith.sub %0, %1 : f32
  %3 = arith.constant {value = 0} : i32
  kd.store %2, %a, %3
  func.return
}
"""


def test_every_pure_op_with_an_interp_rule_has_a_folder():
    for opdef in CATALOG:
        if PURE in opdef.traits and opdef.interp is not None:
            assert opdef.folder is not None, opdef.name


def test_the_default_folder_is_the_interp_rule():
    text = print_module(run_pipeline(parse_module(SRC), "fold"))
    assert "arith.sub" not in text and "{value = 5.0} : f32" in text


def test_the_fold_pass_calls_the_op_folder(monkeypatch):
    seen = []

    def folder(op, args):
        seen.append([float(a) for a in args])
        return [42.0]

    monkeypatch.setattr(CATALOG["arith.sub"], "folder", folder)
    text = print_module(run_pipeline(parse_module(SRC), "fold"))
    assert seen == [[7.0, 2.0]] and "{value = 42.0} : f32" in text


def test_a_declining_or_failing_folder_keeps_the_op(monkeypatch):
    for result in (lambda op, args: None, lambda op, args: 1 / 0):
        monkeypatch.setattr(CATALOG["arith.sub"], "folder", result)
        assert "arith.sub" in print_module(run_pipeline(parse_module(SRC), "fold"))


def test_literals_fold_with_python_arithmetic():
    assert fold_literal("arith.add", 2**70, 1) == 2**70 + 1  # unbounded, still a literal
    assert fold_literal("arith.mul", 1.5, 2) == 3.0
    assert fold_literal("arith.pow", 2, 10) == 1024
    assert fold_literal("arith.xor", True, True) is False
    assert fold_literal("arith.div", 1, 4.0) == 0.25
    assert fold_literal("arith.neg", 3) == -3 and fold_literal("arith.not", 0) is True
    assert fold_literal("arith.cmp", 2, 3.5, pred="lt") is True
    assert math.isnan(fold_literal("arith.sub", math.inf, math.inf))


@pytest.mark.parametrize(
    "name, a, b",
    [
        ("arith.div", 7, 2),  # integer division keeps C's semantics: typed, then emitted
        ("arith.div", 1.0, 0),  # float division by zero: typed (gives inf at run time)
        ("arith.pow", 2, -1),
        ("arith.floordiv", 7, 2),
        ("arith.mod", 7, 2),
        ("arith.shl", 1, 3),
        ("vec.matmul", 1, 2),  # no literal folder
        ("arith.matmul", 1, 2),  # no such op
    ],
)
def test_literals_the_catalog_declines_to_fold(name, a, b):
    assert fold_literal(name, a, b) is None
