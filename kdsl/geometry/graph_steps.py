"""A geometry build's prepared steps replayed as one CUDA graph from their second run.

A GPU rebuild (a hash grid's counting sort, an lbvh build with the kdsl sort) is a
list of prepared kernel launches on one stream, each costing a few microseconds of
host time. ``StepGraph`` runs them one by one the first time (a build that is never
repeated pays no capture), captures them as one graph the second time, and replays
the graph from then on: one graph launch of host time. While a capture of the user's
is open the steps run one by one (they join it); a failed capture leaves them one by
one for good.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from typing import Any

from kdsl.errors import KdslError
from kdsl.runtime.graphs import state as graphs
from kdsl.runtime.graphs.capture import capture_begin, capture_end, capture_launch


def graphs_on(device: Any) -> bool:
    """Whether builds on ``device`` replay their steps as graphs (CUDA's; the CPU's
    captures replay launch by launch, which saves nothing)."""
    return bool(device.is_cuda)


def capture_steps(steps: list[Callable[[], None]], stream: Any) -> Callable[[], None] | None:
    """``steps`` (kernel launches on the CUDA ``stream``) captured as one graph: a
    callable that replays it on ``stream``; None when the capture fails, a step
    included (a captured step runs nothing, so the caller runs them one by one, and a
    step's own error comes again there)."""
    try:
        capture_begin(stream=stream)
    except KdslError:
        return None
    try:
        for step in steps:
            step()
    except Exception:
        with contextlib.suppress(Exception):
            capture_end(stream=stream)
        return None
    except BaseException:
        with contextlib.suppress(Exception):
            capture_end(stream=stream)
        raise
    try:
        graph = capture_end(stream=stream)
    except Exception:
        return None
    return lambda: capture_launch(graph, stream)


class StepGraph:
    """``steps`` run one by one, or, when ``graphed``, as a graph on ``stream`` from
    their second run (see the module docstring). ``drop()`` forgets the graph (after a
    change to a step's arguments) and counts runs anew."""

    __slots__ = ("graph", "graphed", "runs", "steps", "stream")

    def __init__(self, steps: list[Callable[[], None]], stream: Any, graphed: bool) -> None:
        self.steps, self.stream, self.graphed = steps, stream, graphed
        self.runs = 0
        self.graph: Callable[[], None] | None = None

    def drop(self) -> None:
        """Forget the graph: the next run goes one by one, the one after captures."""
        self.graph, self.runs = None, 0

    def __call__(self) -> None:
        """Run the steps."""
        if graphs.ACTIVE or not self.graphed:
            self._each()
            return
        if self.graph is None and self.runs:
            self.graph = capture_steps(self.steps, self.stream)
            self.graphed = self.graph is not None  # a failed capture: one by one from now
        if self.graph is not None:
            self.graph()
        else:
            self._each()
        self.runs += 1

    def _each(self) -> None:
        for step in self.steps:
            step()
