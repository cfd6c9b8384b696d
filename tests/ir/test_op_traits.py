"""The facts passes read from the op catalog (traits and memory operands) hold."""

import numpy as np
import pytest

from kdsl.ir import CATALOG
from kdsl.ir.catalog import (
    CONSTANT_LIKE,
    INVOLUTION,
    PURE,
    READS,
    RECURSIVE_EFFECTS,
    SPECULATABLE,
    TERMINATOR,
    WRITES,
)
from kdsl.ir.ops_arith import NEG, NOT
from kdsl.ir.ops_mem import ATOMIC_CAS, ATOMIC_RMW, LOAD, STORE


def test_ops_are_defined_once_and_the_handles_are_the_catalog_entries():
    from kdsl.ir import ops_arith, ops_debug, ops_func, ops_mem, ops_scf, ops_vec

    for module in (ops_arith, ops_debug, ops_func, ops_mem, ops_scf, ops_vec):
        for value in vars(module).values():
            if type(value).__name__ == "OpDef":
                assert CATALOG[value.name] is value


def test_memory_operands():
    assert [LOAD.array_operand, STORE.array_operand] == [0, 1]
    assert [ATOMIC_RMW.array_operand, ATOMIC_CAS.array_operand] == [1, 2]
    assert [STORE.stored_operand, ATOMIC_RMW.stored_operand] == [0, 0]
    assert LOAD.stored_operand is None and ATOMIC_CAS.stored_operand is None
    for opdef in CATALOG:
        if opdef.array_operand is not None:
            assert opdef.traits & {READS, WRITES}, opdef.name
        if opdef.stored_operand is not None:
            assert WRITES in opdef.traits and opdef.array_operand is not None, opdef.name


def test_trait_consistency():
    for opdef in CATALOG:
        t = opdef.traits
        assert not (PURE in t and t & {READS, WRITES}), opdef.name
        if SPECULATABLE in t:
            assert PURE in t, opdef.name
        if RECURSIVE_EFFECTS in t:
            assert opdef.num_regions > 0 and PURE not in t, opdef.name
        if CONSTANT_LIKE in t:
            assert PURE in t and "value" in opdef.required_attrs, opdef.name
        if TERMINATOR in t:
            assert not t & {PURE, WRITES}, opdef.name
    structured = {o.name for o in CATALOG if RECURSIVE_EFFECTS in o.traits}
    assert structured == {"scf.if", "scf.for", "scf.while"}


@pytest.mark.parametrize("opdef", [NEG, NOT], ids=lambda o: o.name)
def test_involutions_undo_themselves(opdef):
    assert INVOLUTION in opdef.traits
    values = [np.bool_(True), np.bool_(False)] if opdef is NOT else [
        np.float32(-1.5), np.int32(-(2**31)), np.int8(7), np.float64(0.0)
    ]  # fmt: skip
    for x in values:
        twice = opdef.interp(None, None, opdef.interp(None, None, x))
        assert twice == x and type(twice) is type(x)
