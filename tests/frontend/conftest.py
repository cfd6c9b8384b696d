"""Helpers for frontend tests: FileCheck-style matching and the round-trip check."""

from __future__ import annotations

import re

import pytest

from kdsl.ir import parse_module, print_module, verify_module


def check_ir(text: str, checks: str) -> None:
    """Match ``CHECK:``, ``CHECK-NEXT:`` and ``CHECK-NOT:`` lines against ``text`` in order.

    A pattern matches as a substring of a line; ``{{re}}`` embeds a regular expression.
    """
    lines = text.splitlines()
    pos = 0  # index of the next line to search from
    last = -1  # index of the line the previous CHECK matched
    pending_not: list[str] = []
    for raw in checks.strip().splitlines():
        kind, _, pat = raw.strip().partition(":")
        rx = _compile(pat.strip())
        if kind == "CHECK-NOT":
            pending_not.append(pat.strip())
            continue
        if kind == "CHECK":
            hit = next((k for k in range(pos, len(lines)) if rx.search(lines[k])), None)
        elif kind == "CHECK-NEXT":
            hit = last + 1 if last + 1 < len(lines) and rx.search(lines[last + 1]) else None
        else:
            raise ValueError(f"unknown check {raw!r}")
        if hit is None:
            pytest.fail(f"{kind}: {pat.strip()!r} not found after line {pos}:\n{text}")
        for n in pending_not:
            for k in range(pos, hit):
                if _compile(n).search(lines[k]):
                    pytest.fail(f"CHECK-NOT: {n!r} matched line {k}: {lines[k]}\n{text}")
        pending_not = []
        last, pos = hit, hit + 1
    for n in pending_not:
        for k in range(pos, len(lines)):
            if _compile(n).search(lines[k]):
                pytest.fail(f"CHECK-NOT: {n!r} matched line {k}: {lines[k]}\n{text}")


def _compile(pat: str) -> re.Pattern[str]:
    parts = re.split(r"\{\{(.*?)\}\}", pat)
    return re.compile("".join(re.escape(p) if i % 2 == 0 else p for i, p in enumerate(parts)))


def build_text(kernel) -> str:
    """Build, verify and print ``kernel``'s module; assert print -> parse -> print is stable."""
    module = kernel.build_module()
    verify_module(module)
    text = print_module(module)
    assert print_module(parse_module(text)) == text
    return text


@pytest.fixture(name="check_ir")
def check_ir_fixture():
    """The ``check_ir`` helper as a fixture."""
    return check_ir


@pytest.fixture(name="build_text")
def build_text_fixture():
    """The ``build_text`` helper as a fixture."""
    return build_text
