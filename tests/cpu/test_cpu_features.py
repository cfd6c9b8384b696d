"""The cpu backend declares a C library function only for a feature the analysis lists."""

from __future__ import annotations

import pytest
from llvmlite import ir

import kdsl as wp
from kdsl.backends.cpu.emitter import Emitter
from kdsl.backends.cpu.lower import lower_kernels, new_module
from kdsl.errors import KdslError
from kdsl.passes import DEFAULT_PIPELINE, run_pipeline
from kdsl.passes.features import analyze_features


@wp.kernel
def saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
    i = wp.tid()
    y[i] = a * x[i] + y[i]


@wp.kernel
def uses_print(y: wp.array(dtype=float)):
    i = wp.tid()
    print(y[i])


@wp.kernel
def uses_tan(y: wp.array(dtype=float), z: wp.array(dtype=wp.float64)):
    i = wp.tid()
    y[i] = wp.tan(y[i])
    z[i] = wp.tan(z[i])


def _module(kernel):
    m = kernel.build_module()
    run_pipeline(m, DEFAULT_PIPELINE)
    return m


def _declared(kernel) -> set[str]:
    """The functions the kernel's LLVM module declares, LLVM intrinsics left out."""
    llmod = lower_kernels(_module(kernel), [kernel.key]).llmod
    return {f.name for f in llmod.functions if f.is_declaration and not f.name.startswith("llvm.")}


def test_saxpy_declares_nothing():
    assert analyze_features(_module(saxpy)).names == frozenset()
    assert _declared(saxpy) == set()


def test_print_declares_printf_and_math_declares_its_libm_functions():
    assert _declared(uses_print) == {"printf"}
    names = analyze_features(_module(uses_tan)).names
    assert {"math.tan", "f64"} <= names and "print" not in names
    assert _declared(uses_tan) == {"tanf", "tan"}


def test_a_declaration_of_a_feature_the_analysis_does_not_list_is_refused():
    state = new_module(_module(saxpy))
    printf = ir.FunctionType(ir.IntType(32), [ir.PointerType(ir.IntType(8))], var_arg=True)
    with pytest.raises(KdslError, match="feature 'print'"):
        state.declare("printf", printf)
    fn = ir.Function(state.llmod, ir.FunctionType(ir.FloatType(), [ir.FloatType()]), "f")
    em = Emitter(state, fn, "f")
    em.b.position_at_end(fn.append_basic_block("entry"))
    with pytest.raises(KdslError, match=r"feature 'math\.tan'"):
        em.libm("tan", fn.args[0])
