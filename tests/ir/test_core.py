"""Use-list integrity, constant normalization and the reference numeric semantics."""

from __future__ import annotations

import math

import numpy as np
import pytest

from kdsl.ir import Builder, Module, new_func, types, verify_module
from kdsl.ir import semantics as sem
from kdsl.ir.builder import normalize_constant


def _func():
    m = Module()
    f = new_func(m, "f", [types.I32, types.I32], ["a", "b"], [types.I32], "func")
    block = f.regions[0].block
    return m, block, Builder(block), block.args


def _uses_consistent(module: Module) -> None:
    for op in module.walk():
        for i, v in enumerate(op.operands):
            assert (op, i) in v.uses
        for r in op.results:
            for user, i in r.uses:
                assert user.operands[i] is r


def test_replace_all_uses_and_erase_keep_use_lists_exact():
    m, _block, b, (a, c) = _func()
    s = b.value("arith.add", a, a)
    t = b.value("arith.mul", s, c)
    ret = b.create("func.return", [t])
    assert s.uses == [(t.op, 0)] and len(a.uses) == 2
    s.replace_all_uses_with(c)
    assert s.uses == [] and t.op.operands == [c, c]
    assert (t.op, 0) in c.uses and (t.op, 1) in c.uses
    s.op.erase()
    assert a.uses == [] and s.op.parent is None
    _uses_consistent(m)
    verify_module(m)
    with pytest.raises(ValueError, match="still used"):
        t.op.erase()
    ret.set_operand(0, a)
    t.op.erase()
    assert c.uses == [] and a.uses == [(ret, 0)]
    verify_module(m)


def test_set_operands_and_erase_nested():
    m = Module()
    f = new_func(m, "k", [types.BOOL, types.F32], ["c", "x"], [], "kernel")
    block = f.regions[0].block
    b = Builder(block)
    c, x = block.args
    from kdsl.ir import Block, Region, create_op

    then_b, else_b = Block(), Block()
    with b.at_end(then_b):
        y = b.value("arith.mul", x, x)
        b.create("scf.yield", [y])
    with b.at_end(else_b):
        b.create("scf.yield", [x])
    if_op = b.create("scf.if", [c], [types.F32], regions=[Region(then_b), Region(else_b)])
    b.create("func.return")
    verify_module(m)
    assert len(x.uses) == 3
    if_op.erase()  # nested ops drop their operands too
    assert x.uses == [] and c.uses == []
    op = create_op("arith.add", [x, x])
    op.set_operands([x])
    assert x.uses == [(op, 0)]
    op.drop_operands()
    assert x.uses == []


@pytest.mark.parametrize(
    "value, t, want",
    [
        (1.1, types.F32, float(np.float32(1.1))),
        (1.1, types.F64, 1.1),
        (70000.0, types.F16, math.inf),
        (300, types.U8, 44),
        (-1, types.U32, 2**32 - 1),
        (2**31, types.I32, -(2**31)),
        (2.9, types.I32, 2),
        (float("nan"), types.I64, 0),
        (1e30, types.I64, 2**63 - 1),
        (-1e30, types.I64, -(2**63)),
        (1e30, types.U64, 2**64 - 1),
        (2, types.BOOL, True),
        (0.0, types.BOOL, False),
    ],
)
def test_normalize_constant(value, t, want):
    got = normalize_constant(value, t)
    assert type(got) is type(want) and got == want


def test_normalize_constant_keeps_nan_and_negative_zero():
    assert math.isnan(normalize_constant(float("nan"), types.F32))
    assert math.copysign(1.0, normalize_constant(-0.0, types.F16)) == -1.0


def _i32(*xs):
    return np.array(xs, dtype=np.int32)


def test_int_division_truncates_and_zero_divisor_gives_zero():
    a, b = _i32(7, -7, 7, -7, 5, -(2**31)), _i32(2, 2, -2, -2, 0, -1)
    assert sem.int_div(a, b).tolist() == [3, -3, -3, 3, 0, -(2**31)]
    assert sem.int_floordiv(a, b).tolist() == [3, -4, -4, 3, 0, -(2**31)]
    assert sem.int_mod(a, b).tolist() == [1, -1, 1, -1, 0, 0]


def test_saturating_float_to_int_casts():
    x = np.array([np.nan, np.inf, -np.inf, 3.99, -3.99, 1e20, -1e20], dtype=np.float64)
    assert sem.cast_scalar_array(x, types.I32).tolist() == [
        0, 2**31 - 1, -(2**31), 3, -3, 2**31 - 1, -(2**31)
    ]  # fmt: skip
    assert sem.cast_scalar_array(x, types.U8).tolist() == [0, 255, 0, 3, 0, 255, 0]
    big = np.array([2.0**63, -(2.0**63), 2.0**64], dtype=np.float64)
    assert sem.cast_scalar_array(big, types.I64).tolist() == [2**63 - 1, -(2**63), 2**63 - 1]
    assert sem.cast_scalar_array(big, types.U64).tolist() == [2**63, 0, 2**64 - 1]
    f32 = np.array([np.nan], dtype=np.float32)
    assert sem.cast_scalar_array(f32, types.I64).tolist() == [0]


def test_integer_casts_wrap_and_bool_is_nonzero():
    assert sem.cast_scalar_array(_i32(-1, 256, 257), types.U8).tolist() == [255, 0, 1]
    assert sem.cast_scalar_array(np.array([0.0, -0.0, 0.5, np.nan]), types.BOOL).tolist() == [
        False, False, True, True
    ]  # fmt: skip


def test_shifts_by_width_or_more():
    a = _i32(1, 1, 1, -8, -8, 8)
    s = _i32(31, 32, 40, 1, 32, 33)
    assert sem.shift_left(a, s).tolist() == [-(2**31), 0, 0, -16, 0, 0]
    assert sem.shift_right(a, s).tolist() == [0, 0, 0, -4, -1, 0]
    u = np.array([2**63], dtype=np.uint64)
    assert sem.shift_right(u, np.array([64], dtype=np.uint64)).tolist() == [0]
    assert sem.shift_left(_i32(1), _i32(-1)).tolist() == [0]


def test_round_half_away_from_zero():
    x = np.array([0.5, -0.5, 1.5, 2.5, -2.5, 0.49999997], dtype=np.float32)
    assert sem.round_half_away(x).tolist() == [1.0, -1.0, 2.0, 3.0, -3.0, 0.0]
