"""Every op of the catalog is lowered (or declared a gap) on every built-in backend."""

import importlib

import pytest

from kdsl.ir import CATALOG
from kdsl.ir.lowering import LOWERINGS, LoweringRegistry

#: The module of each built-in backend that registers all of its lowerings.
BUILTIN = {
    "cpu": "kdsl.backends.cpu.ops",
    "cuda": "kdsl.backends.cuda.ops",
    "interp": "kdsl.backends.interp.program",
}


@pytest.fixture(scope="module", autouse=True)
def _builtin_lowerings():
    for module in BUILTIN.values():
        importlib.import_module(module)


@pytest.mark.parametrize("backend", sorted(BUILTIN))
def test_every_op_has_a_lowering_or_a_declared_gap(backend):
    missing = LOWERINGS.uncovered(backend)
    assert not missing, f"{backend} neither lowers nor declares: {missing}"
    for opdef in CATALOG:
        c = LOWERINGS.coverage(opdef, backend)
        assert c.op == opdef.name and c.backend == backend
        if c.kind in ("rule", "default"):
            assert callable(c.rule), (opdef.name, backend)
        else:
            assert c.rule is None and c.note.strip(), (opdef.name, backend, c.kind)


@pytest.mark.parametrize("backend", ["cpu", "cuda"])
def test_dispatch_table_is_the_registry(backend):
    ops = importlib.import_module(BUILTIN[backend])
    assert ops.TABLE is LOWERINGS.table(backend)
    for name, rule in ops.TABLE.items():
        assert LOWERINGS.get(name, backend) is rule


def test_interp_lowers_through_the_catalog_rules():
    for opdef in CATALOG:
        c = LOWERINGS.coverage(opdef, "interp")
        if opdef.interp is not None:
            assert c.kind == "default" and c.rule is opdef.interp
        else:
            assert c.kind == "structural"


def test_terminators_are_structural_everywhere():
    fresh = LoweringRegistry()  # a new backend declares nothing for them
    for opdef in CATALOG:
        if opdef.is_terminator:
            for backend in BUILTIN:
                assert LOWERINGS.coverage(opdef, backend).kind == "structural"
            assert fresh.coverage(opdef, "toy").kind == "structural"
        else:
            assert fresh.coverage(opdef, "toy") is None


def test_a_second_lowering_is_refused_naming_both():
    reg = LoweringRegistry()

    def first(em, op):
        return None

    def second(em, op):
        return None

    reg.register("arith.add", "toy", first)
    with pytest.raises(ValueError) as info:
        reg.register("arith.add", "toy", second)
    msg = str(info.value)
    assert "'toy'" in msg and "arith.add" in msg and "twice" in msg
    assert "first" in msg and "second" in msg and __file__ in msg
    assert reg.get("arith.add", "toy") is first  # the refused one changed nothing
    reg.register("arith.add", "other", second)  # another backend may lower it too


def test_a_gap_or_structural_op_counts_as_a_declaration():
    reg = LoweringRegistry()
    toy = reg.for_backend("toy")
    toy.gap("kd.atomic_cas", "no 64-bit compare-and-swap on this target")
    with pytest.raises(ValueError, match=r"declares kd\.atomic_cas twice"):
        toy.register("kd.atomic_cas", lambda em, op: None)
    toy.structural("scf.yield", "read by the parent op")
    with pytest.raises(ValueError, match="twice"):
        toy.gap("scf.yield", "no")
    with pytest.raises(ValueError, match="needs a reason"):
        toy.gap("kd.load", "  ")
    assert reg.coverage("kd.atomic_cas", "toy").kind == "gap"
    assert reg.get("kd.atomic_cas", "toy") is None
    assert "kd.atomic_cas" not in reg.uncovered("toy")
    assert "kd.load" in reg.uncovered("toy")


def test_the_live_registry_refuses_a_second_cpu_lowering():
    with pytest.raises(ValueError, match=r"'cpu' declares arith\.add twice"):
        LOWERINGS.register("arith.add", "cpu", lambda em, op: None)


def test_unknown_ops_are_refused():
    reg = LoweringRegistry()
    with pytest.raises(KeyError, match="no such op"):
        reg.register("arith.addd", "toy", lambda em, op: None)


def test_decorator_and_default():
    reg = LoweringRegistry()

    @reg.lowering("math.sin", "toy")
    def _sin(em, op):
        return "sin"

    assert reg.get("math.sin", "toy") is _sin
    reg.set_default("toy", lambda opdef: opdef.interp, "the interp rule")
    assert reg.get("math.sin", "toy") is _sin  # a registered rule wins over the default
    assert reg.get("math.cos", "toy") is CATALOG["math.cos"].interp
    assert reg.coverage("math.cos", "toy").kind == "default"
    with pytest.raises(ValueError, match="default"):
        reg.set_default("toy", lambda opdef: None, "again")
