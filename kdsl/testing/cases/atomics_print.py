"""Conformance cases: atomics_print (issue 5)."""

from kdsl.testing.case import Case

CASES: list[Case] = []
