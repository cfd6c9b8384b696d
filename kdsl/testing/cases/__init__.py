"""The conformance cases, grouped by area; ``all_cases()`` lists them all."""

from __future__ import annotations

import importlib

from kdsl.testing.case import Case

#: Case modules, one per area, in the order the suite runs them.
GROUPS = ("arith", "logic", "math", "vector", "control", "funcs", "memory", "programs",
          "scalar_math", "linalg", "geometry", "random_noise", "atomics_print",
          "gradients", "structs", "warp_ops")


def all_cases() -> list[Case]:
    """Every case of every group; names are unique."""
    cases: list[Case] = []
    for group in GROUPS:
        module = importlib.import_module(f"kdsl.testing.cases.{group}")
        cases.extend(module.CASES)
    names = [c.name for c in cases]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise ValueError(f"duplicate conformance case names: {dupes}")
    return cases
