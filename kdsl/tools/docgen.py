"""The command line shared by kdsl's generated documentation pages."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path


def write_or_check(
    argv: list[str] | None, description: str, output: Path, render: Callable[[], str], how: str
) -> int:
    """Write ``render()`` to ``output``, or with ``--check`` fail (1) when it is stale.

    ``how`` is the command that regenerates the page, for the staleness message.
    """
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--check", action="store_true", help=f"fail if {output.name} is stale")
    parser.add_argument("--output", type=Path, default=output)
    args = parser.parse_args(argv)
    text = render()
    if args.check:
        current = args.output.read_text() if args.output.exists() else ""
        if current != text:
            print(f"{args.output} is out of date: run {how}", file=sys.stderr)
            return 1
        return 0
    args.output.write_text(text)
    print(f"wrote {args.output}")
    return 0
