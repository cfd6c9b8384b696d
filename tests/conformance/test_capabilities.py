"""Capabilities are true: each one a backend advertises is exercised by a conformance
case that passes on it, and a kernel needing one it does not advertise is refused with
a located ``KdslCapabilityError`` (issue 13)."""

import functools

import pytest

import kdsl as wp
from kdsl.backends import registry
from kdsl.backends.interp.backend import InterpBackend
from kdsl.compiler import compile_kernel
from kdsl.compiler.capabilities import DESCRIPTION, required_capabilities
from kdsl.errors import KdslCapabilityError
from kdsl.testing.case import Case
from kdsl.testing.cases import all_cases
from kdsl.testing.conformance import check_case

BACKENDS = [
    "interp",
    "cpu",
    pytest.param("cuda", marks=pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")),
]


@functools.cache
def _case_needs(case: Case) -> frozenset[str]:
    return required_capabilities(case.kernel.build_module())


def _case_exercising(cap: str) -> Case:
    """The first plain case whose kernel needs ``cap`` (declared ones tried first)."""
    cases = [c for c in all_cases() if isinstance(c, Case) and not c.kernel.is_generic]
    cases.sort(key=lambda c: cap not in c.requires)  # stable: declared first
    for case in cases:
        if cap in _case_needs(case):
            return case
    raise AssertionError(f"no conformance case exercises the capability {cap!r}")


@pytest.mark.parametrize("backend", BACKENDS)
def test_every_advertised_capability_is_exercised_by_a_passing_case(backend):
    caps = registry.get_backend(backend).capabilities
    unknown = set(caps) - set(DESCRIPTION)
    assert not unknown, f"{backend} advertises capabilities no check knows: {unknown}"
    for cap in sorted(caps):
        case = _case_exercising(cap)
        assert cap in case.requires or cap == "fp32", (
            f"case {case.name} needs {cap} but does not declare it in requires="
        )
        check_case(case, backend)  # AssertionError on a wrong output


def test_no_backend_advertises_recursion():
    # The frontend refuses recursive @funcs, so no backend may claim to run them.
    for name in registry.available_backends():
        assert "recursion" not in registry.get_backend(name).capabilities


class _NoFp64(InterpBackend):
    name = "interp-no-fp64"
    capabilities = InterpBackend.capabilities - {"fp64"}


@wp.kernel
def _widen(x: wp.array(dtype=wp.float32), y: wp.array(dtype=wp.float64)):
    i = wp.tid()
    y[i] = wp.float64(x[i]) * wp.float64(2.0)


def test_unadvertised_capability_is_refused_with_the_source_line():
    with pytest.raises(KdslCapabilityError) as info:
        compile_kernel(_NoFp64(), _widen)
    text = str(info.value)
    assert "the interp-no-fp64 backend does not support fp64 (float64 values)" in text
    assert __file__ in text and "def _widen(" in text  # the first line that needs it
