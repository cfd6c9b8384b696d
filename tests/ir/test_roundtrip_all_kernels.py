"""Print -> parse -> print is exact for every kernel kdsl's own suites compile.

Covers each conformance kernel as the frontend builds it and after the standard
pipeline, with and without source locations, and checks the parsed module
verifies. A printer/parser mismatch on any construct the frontend emits fails here.
"""

from __future__ import annotations

import pytest

from kdsl.ir import parse_module, print_module
from kdsl.passes import DEFAULT_PIPELINE, run_pipeline
from kdsl.testing.cases import all_cases

CASES = all_cases()


def _roundtrip(module, debuginfo: bool) -> None:
    text = print_module(module, debuginfo=debuginfo)
    again = print_module(parse_module(text, verify=True), debuginfo=debuginfo)
    assert again == text


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_kernel_ir_roundtrips(case):
    module = case.kernel.build_module()
    for debuginfo in (False, True):
        _roundtrip(module, debuginfo)
    run_pipeline(module, DEFAULT_PIPELINE)
    for debuginfo in (False, True):
        _roundtrip(module, debuginfo)


def test_every_case_was_checked():
    assert len(CASES) >= 60
