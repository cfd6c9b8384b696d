"""A differential fuzzer of kdsl programs (docs/testing.md, "Differential fuzzing").

``generate.programs()`` and ``invalid.invalid_programs()`` are Hypothesis strategies of
programs (``program.Program``, printed as Python by ``Program.source()``);
``check.check_valid``/``check.check_invalid`` are the oracles; ``run.fuzz`` is the
long-running loop behind ``python -m kdsl.testing.fuzz``.
"""

from kdsl.testing.fuzz.check import FuzzFailure, check_invalid, check_valid, is_internal
from kdsl.testing.fuzz.generate import ALL_FEATURES, programs
from kdsl.testing.fuzz.invalid import invalid_programs
from kdsl.testing.fuzz.program import Program
from kdsl.testing.fuzz.run import KNOWN_ISSUES, Summary, check_program, fuzz

__all__ = [
    "ALL_FEATURES", "FuzzFailure", "KNOWN_ISSUES", "Program", "Summary", "check_invalid",
    "check_program", "check_valid", "fuzz", "invalid_programs", "is_internal", "programs",
]  # fmt: skip
