"""The IR text form: print -> parse -> print is exact, for every kind of type and attr."""

from __future__ import annotations

import pytest

from kdsl.ir import Builder, Module, new_func, parse_module, print_module, types
from kdsl.ir.core import Loc

ALL_TYPES = """\
struct Particle {pos: vec<3, f32>, mass: f64, ids: vec<2, i64>}

func.func @types(%a: bool, %b: i8, %c: u16, %d: u64, %e: f16, %f: f64, %g: vec<4, f16>, %h: mat<2, 3, f64>, %q: quat<f32>, %t: transform<f64>, %s: struct<Particle>, %arr: array<vec<3, f32>, 2>, %parr: array<struct<Particle>, 1>, %m: handle<mesh>, %v: handle<volume>) -> (f64) {kind = "func"} {
  %p = struct.extract %s {field = "mass"} : f64
  func.return %p
}
"""

ATTRS = """\
func.func @attrs() -> () {kind = "kernel", note = "say \\"hi\\" \\\\ there", tags = [1, -2, 3.5]} {
  %nan = arith.constant {value = nan} : f32
  %inf = arith.constant {value = inf} : f64
  %ninf = arith.constant {value = -inf} : f64
  %neg = arith.constant {value = -7} : i64
  %nz = arith.constant {value = -0.0} : f32
  %tiny = arith.constant {value = 5e-324} : f64
  %big = arith.constant {value = 18446744073709551615} : u64
  %t = arith.constant {value = true} : bool
  func.return
}
"""


@pytest.mark.parametrize("text", [ALL_TYPES, ATTRS])
def test_print_parse_print_is_exact(text):
    once = print_module(parse_module(text))
    assert once == text
    assert print_module(parse_module(once)) == once


def test_struct_definition_and_types_parse_to_objects():
    m = parse_module(ALL_TYPES)
    st = m.structs["Particle"]
    assert st.fields[0] == ("pos", types.VectorType(3, types.F32))
    args = m.get_func("types").regions[0].block.args
    assert isinstance(args[8].type, types.QuatType)
    assert isinstance(args[9].type, types.TransformType)
    assert args[11].type == types.ArrayType(types.VectorType(3, types.F32), 2)
    assert args[13].type == types.HandleType("mesh")


def test_attribute_values_survive():
    import math

    m = parse_module(ATTRS)
    ops = m.get_func("attrs").regions[0].block.ops
    values = [op.attrs["value"] for op in ops[:-1]]
    assert math.isnan(values[0])
    assert values[1:4] == [math.inf, -math.inf, -7]
    assert math.copysign(1.0, values[4]) == -1.0
    assert values[5] == 5e-324 and values[6] == 2**64 - 1 and values[7] is True
    assert m.get_func("attrs").attrs["note"] == 'say "hi" \\ there'


def test_locations_round_trip_with_debuginfo():
    m = Module()
    f = new_func(m, "k", [types.F32], ["x"], [], "kernel", loc=Loc("k.py", 1, 1, 9, 0))
    b = Builder(f.regions[0].block)
    with b.at(Loc("dir/my kernel.py", 12, 9, 12, 20)):
        x = f.regions[0].block.args[0]
        b.value("arith.add", x, x)
    with b.at(Loc("k.py", 13, 5)):
        b.create("func.return")
    text = print_module(m, debuginfo=True)
    assert 'loc("dir/my kernel.py":12:9:12:20)' in text
    assert 'loc("k.py":13:5)' in text
    again = parse_module(text)
    assert print_module(again, debuginfo=True) == text
    op = again.get_func("k").regions[0].block.ops[0]
    assert op.loc == Loc("dir/my kernel.py", 12, 9, 12, 20)
    assert "loc(" not in print_module(again)


def test_name_collisions_get_suffixes():
    m = Module()
    f = new_func(m, "f", [types.I32], ["x"], [types.I32], "func")
    b = Builder(f.regions[0].block)
    x = f.regions[0].block.args[0]
    y = b.value("arith.add", x, x)
    y.name_hint = "x"
    b.create("func.return", [y])
    text = print_module(m)
    assert "%x_1 = arith.add %x, %x : i32" in text
    assert print_module(parse_module(text)) == text
