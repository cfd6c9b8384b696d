"""The bounds-check and fp-check passes and the debug ops they insert."""

from __future__ import annotations

import pytest

from kdsl.errors import KdslVerifyError
from kdsl.ir import parse_module, print_module
from kdsl.ir.ops_debug import debug_sites, next_site
from kdsl.passes import run_pipeline

SRC = """func.func @k(%x: array<f32, 1>, %m: array<i32, 2>, %y: array<f32, 1>) -> () {kind = "kernel"} {
  %i = kd.tid {dim = 0, ndim = 1} : i32
  %a = kd.load %x, %i : f32
  %b = kd.load %m, %i, %i : i32
  %f = arith.cast %b : f32
  %s = arith.add %a, %f : f32
  kd.store %s, %y, %i
  %old = kd.atomic_rmw %b, %m, %i, %i {kind = "add"} : i32
  func.return
}
"""


def ops_of(module):
    return [op.name for op in module.get_func("k").walk()][1:]


def test_bounds_check_guards_every_access_with_a_new_site():
    module = run_pipeline(parse_module(SRC), "bounds-check")
    names = ops_of(module)
    for access in ("kd.load", "kd.store", "kd.atomic_rmw"):
        for k, name in enumerate(names):
            if name == access:
                assert names[k - 1] == "kd.check_bounds"
    sites = debug_sites(module)
    assert sorted(sites) == [0, 1, 2, 3]
    assert [s.arg for s in sites.values()] == ["x", "m", "y", "m"]
    assert [s.ndim for s in sites.values()] == [1, 2, 1, 2]
    assert next_site(module) == 4


def test_bounds_check_is_idempotent_and_survives_cleanup():
    module = run_pipeline(parse_module(SRC), "bounds-check")
    once = print_module(module)
    run_pipeline(module, "bounds-check,fold,canonicalize,cse,dce")
    assert print_module(module).count("kd.check_bounds") == 4
    assert print_module(run_pipeline(parse_module(once), "bounds-check")) == once


def test_fp_check_only_guards_float_stores():
    module = run_pipeline(parse_module(SRC), "bounds-check,fp-check")
    text = print_module(module)
    assert text.count("kd.check_finite") == 1
    assert "kd.check_finite %s" in text
    site = [s for s in debug_sites(module).values() if s.op == "kd.check_finite"]
    assert len(site) == 1 and site[0].arg == "y"
    # The bounds check stays right before its store; reruns change nothing.
    names = ops_of(module)
    assert names[names.index("kd.store") - 1] == "kd.check_bounds"
    assert not run_pipeline_changed(module, "fp-check,bounds-check")


def run_pipeline_changed(module, pipeline):
    from kdsl.passes import PassManager

    return PassManager(pipeline).run(module)


@pytest.mark.parametrize(
    "op, message",
    [
        ('kd.check_bounds %x, %i, %i {arg = "x", site = 0}', "needs 1 indices"),
        ('kd.check_bounds %x, %i {arg = "x", site = -1}', "non-negative integer site"),
        ('kd.check_finite %i {arg = "x", site = 0}', "checks float values"),
        ("kd.check_finite %v {site = 0}", "arg"),
    ],
)
def test_verifier_rejects_bad_checks(op, message):
    src = f"""func.func @k(%x: array<f32, 1>, %v: f32) -> () {{kind = "kernel"}} {{
  %i = kd.tid {{dim = 0, ndim = 1}} : i32
  {op}
  func.return
}}
"""
    with pytest.raises(KdslVerifyError, match=message):
        parse_module(src)
