"""The fuzzing loop: generate, check, shrink new failures, save them, summarize.

``fuzz(minutes=...)`` runs rounds of Hypothesis searches until the time is up. In a
round, the first failure whose signature (``FuzzFailure.signature``) is new becomes
the round's target: Hypothesis shrinks it (only failures with that signature count
while it shrinks, so the minimal program shows the same defect), and the minimal
program is saved as ``<dir>/<n>-<kind>.py``. Failures matching ``KNOWN_ISSUES`` (defects
with an owner, listed in docs/testing.md) are counted, not reported again.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import seed as hypothesis_seed
from hypothesis import strategies as st

from kdsl.testing.fuzz.check import FuzzFailure, check_invalid, check_valid
from kdsl.testing.fuzz.generate import programs
from kdsl.testing.fuzz.invalid import invalid_programs
from kdsl.testing.fuzz.program import Program

#: Open defects the fuzzer finds, by a pattern of the failure's text: what they are.
#: Each is written up in docs/testing.md ("Findings"); remove an entry once it is fixed.
#: Empty while every finding is fixed; e.g. ``{r"cannot add values of type struct": "..."}``.
KNOWN_ISSUES: dict[str, str] = {}


def known_issue(failure: FuzzFailure, known: dict[str, str]) -> str | None:
    """The description of the known issue ``failure`` is, or None."""
    text = f"{failure.kind} {failure.detail}"
    for pattern, what in known.items():
        if re.search(pattern, text):
            return what
    return None


def check_program(program: Program, backends: Sequence[str] = ("interp", "cpu")) -> None:
    """Check one fuzzed program, valid or invalid (raises ``FuzzFailure``)."""
    if program.invalid:
        check_invalid(program, backends)
    else:
        check_valid(program, backends)


def any_programs(invalid_share: float = 0.2) -> st.SearchStrategy[Program]:
    """Valid programs, and invalid ones about ``invalid_share`` of the time."""
    percent = round(invalid_share * 100)
    return st.integers(0, 99).flatmap(lambda k: invalid_programs() if k < percent else programs())


@dataclass
class Summary:
    """What a fuzzing run did and found."""

    programs: int = 0
    invalid: int = 0
    seconds: float = 0.0
    rounds: int = 0
    failures: dict[str, Path] = field(default_factory=dict)
    known: dict[str, int] = field(default_factory=dict)

    def text(self) -> str:
        """A human-readable report."""
        lines = [
            f"kdsl fuzz: {self.programs} programs ({self.invalid} invalid) in "
            f"{self.seconds / 60:.1f} min, {self.rounds} rounds",
            f"new failures: {len(self.failures)}",
            *(f"  {sig}\n    minimal program: {path}" for sig, path in self.failures.items()),
        ]
        if self.known:
            lines.append("known issues hit (docs/testing.md, Findings):")
            lines += [f"  {what}: {n} programs" for what, n in self.known.items()]
        return "\n".join(lines)


def fuzz(
    minutes: float,
    backends: Sequence[str] = ("interp", "cpu"),
    seed: int = 0,
    out_dir: Path | str = "fuzz-failures",
    examples_per_round: int = 200,
    known: dict[str, str] | None = None,
    log: Callable[[str], None] = print,
) -> Summary:
    """Fuzz for ``minutes``; save each new failure's minimal program under ``out_dir``."""
    known = KNOWN_ISSUES if known is None else known
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    summary = Summary()
    start = time.monotonic()
    deadline = start + minutes * 60
    seen: set[str] = set()
    while time.monotonic() < deadline:
        test = _RoundTest(summary, seen, known, backends, deadline)
        search = settings(
            max_examples=examples_per_round, deadline=None, database=None,
            suppress_health_check=list(HealthCheck),
            phases=[Phase.generate, Phase.target, Phase.shrink],
        )(hypothesis_seed(seed + summary.rounds)(given(any_programs())(test.check)))  # fmt: skip
        summary.rounds += 1
        try:
            search()
        except FuzzFailure as failure:
            sig = failure.signature()
            seen.add(sig)
            path = out / f"{len(summary.failures) + 1:03d}-{failure.kind.replace('/', '-')}.py"
            path.write_text(_commented(failure))
            summary.failures[sig] = path
            log(f"[{(time.monotonic() - start) / 60:.1f} min] new failure: {sig}\n  saved {path}")
    summary.seconds = time.monotonic() - start
    return summary


@dataclass
class _RoundTest:
    """The property one round checks: the first new failure becomes the round's target,
    and only failures with its signature fail while Hypothesis shrinks it."""

    summary: Summary
    seen: set[str]
    known: dict[str, str]
    backends: Sequence[str]
    deadline: float
    target: str | None = None

    def check(self, program: Program) -> None:
        """Check ``program``; raise only for the round's target failure."""
        if time.monotonic() > self.deadline and self.target is None:
            return  # out of time: let the round end quickly
        self.summary.programs += 1
        self.summary.invalid += bool(program.invalid)
        try:
            check_program(program, self.backends)
        except FuzzFailure as failure:
            what = known_issue(failure, self.known)
            if what is not None:
                self.summary.known[what] = self.summary.known.get(what, 0) + 1
                return
            sig = failure.signature()
            if sig in self.seen or (self.target is not None and sig != self.target):
                return
            self.target = sig
            raise


def _commented(failure: FuzzFailure) -> str:
    """The failing program's source, headed by the failure as comments."""
    head = "".join(f"# {line}\n" for line in f"[{failure.kind}] {failure.detail}".splitlines())
    return head + failure.source


def main_args(argv: Sequence[str] | None = None) -> Any:
    """Parse ``python -m kdsl.testing.fuzz`` arguments."""
    import argparse

    p = argparse.ArgumentParser(prog="python -m kdsl.testing.fuzz",
                                description="Differential fuzzing of kdsl programs.")  # fmt: skip
    p.add_argument("--minutes", type=float, default=5.0, help="how long to run (default 5)")
    p.add_argument("--backends", default="interp,cpu",
                   help="comma-separated backends to compare (default interp,cpu)")  # fmt: skip
    p.add_argument("--seed", type=int, default=0, help="seed of the first round (default 0)")
    p.add_argument("--out", default="fuzz-failures",
                   help="directory for minimal failing programs (default ./fuzz-failures)")  # fmt: skip
    p.add_argument("--all", action="store_true", help="report known issues as failures too")
    return p.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the fuzzer from the command line; exit status 1 when it found new failures."""
    args = main_args(argv)
    backends = [b.strip() for b in args.backends.split(",") if b.strip()]
    summary = fuzz(args.minutes, backends, args.seed, args.out, known={} if args.all else None)
    print(summary.text())
    return 1 if summary.failures else 0
