"""A stand-in for ``kdsl.geometry.graph_steps.capture_steps`` (the CPU's own captures
replay launch by launch, so tests of the replay policy capture with this): the
"graph" is a callable that runs the steps, and the captures and replays are counted."""

from __future__ import annotations

from kdsl.geometry import graph_steps


def counting_capture(monkeypatch) -> dict[str, int]:
    """Patch ``capture_steps`` with the stand-in; the counts of captures and replays."""
    counts = {"captures": 0, "replays": 0}

    def capture(steps, stream):
        counts["captures"] += 1

        def replay() -> None:
            counts["replays"] += 1
            for step in steps:
                step()

        return replay

    monkeypatch.setattr(graph_steps, "capture_steps", capture)
    return counts
