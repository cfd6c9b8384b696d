"""Conformance cases: scalar_math (issue 5)."""

from kdsl.testing.case import Case

CASES: list[Case] = []
