"""Prepared launches in branches that run side by side, forked from a stream and joined
back into it, replayed as one CUDA graph from their second run.

A mesh's refit, behind its check, has three independent pieces of work: the BVH's
bottom-up refit (one launch, latency-bound: a chain of dependent memory round trips as
deep as the tree, while most of the GPU idles), the edge sum (three small launches) and
the gather of the vertex copy (one launch). On one stream they run one after the other;
``ForkedSteps`` issues the first on the stream and each other branch on a side stream
of its own that waits for the work issued on the stream so far (an event), then makes
the stream wait for every branch (one event each): the branches fill the GPU beside the
refit, and work issued after them still sees all of it. The branches' launches must be
prepared on their side streams (``side_streams``). From the second run the fork, the
branches and the join are one CUDA graph (``StepGraph``, whose capture follows the side
streams through the events), so a run costs the host one graph launch. On a CPU (no
streams) the branches run one after the other.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from kdsl.geometry.graph_steps import StepGraph
from kdsl.runtime.device import cuda_device_count, cupy
from kdsl.runtime.stream import Stream

#: Side streams per device ordinal, made on first use and shared by every fork there
#: (a fork's branches are ordered by its events, not by owning their streams).
_SIDE: dict[int, list[Stream]] = {}


def side_streams(device: Any, count: int) -> list[Stream]:
    """``count`` side streams of the CUDA ``device`` (the same ones every call)."""
    held = _SIDE.setdefault(device.ordinal, [])
    while len(held) < count:
        held.append(Stream(device, blocking=False))
    return held[:count]


class ForkedSteps:
    """``head`` then ``main`` (prepared launches on ``stream``) and ``branches`` (pairs of a
    side stream and steps issued on it: launches prepared there, or a read back's
    ``IntsReader.copy_on``) run side by side behind ``head`` and the work issued on
    ``stream`` before, which then waits for all of them (see the module docstring);
    ``graphed``: replayed as one CUDA graph from the second run. ``steps`` lists every
    step (``head``'s first, then ``main``'s)."""

    __slots__ = ("_events", "_graph", "_raw", "branches", "device", "head", "main", "steps",
                 "stream")  # fmt: skip

    def __init__(self, main: Sequence[Callable[[], object]],
                 branches: Sequence[tuple[Stream | None, Sequence[Callable[[], object]]]],
                 stream: Stream | None, graphed: bool,
                 head: Sequence[Callable[[], object]] = ()) -> None:  # fmt: skip
        self.head, self.main, self.stream = list(head), list(main), stream
        self.branches = [(side, list(steps)) for side, steps in branches if steps]
        self.steps = self.head + self.main + [s for _, steps in self.branches for s in steps]
        self.device = None if stream is None else stream.device
        self._events: list[int] = []
        self._raw: tuple = ()
        if stream is not None and self.branches:
            cp = cupy()
            with cp.cuda.Device(self.device.ordinal):
                self._events = [cp.cuda.Event(block=False, disable_timing=True)
                                for _ in range(len(self.branches) + 1)]  # fmt: skip
            self._raw = (stream.cuda_stream, [side.cuda_stream for side, _ in self.branches],
                         [e.ptr for e in self._events])  # fmt: skip
        self._graph = StepGraph([self._run], stream, graphed and stream is not None)

    @property
    def graph(self) -> Callable[[], None] | None:
        """The captured graph's replay, once made (None before the second run)."""
        return self._graph.graph

    def __call__(self) -> None:
        """Run the branches (see the class docstring)."""
        self._graph()

    def _run(self) -> None:
        if not self._raw:  # a CPU, or nothing beside the main launches
            for step in self.steps:
                step()
            return
        if cuda_device_count() == 1:
            self._fork_join()
            return
        rt = cupy().cuda.runtime
        current = rt.getDevice()
        rt.setDevice(self.device.ordinal)
        try:
            self._fork_join()
        finally:
            rt.setDevice(current)

    def _fork_join(self) -> None:
        rt = cupy().cuda.runtime
        main, sides, events = self._raw
        for step in self.head:
            step()
        rt.eventRecord(events[0], main)
        for side in sides:
            rt.streamWaitEvent(side, events[0], 0)
        for step in self.main:  # first: the main branch is the longest
            step()
        for k, (_, steps) in enumerate(self.branches):
            for step in steps:
                step()
            rt.eventRecord(events[k + 1], sides[k])
            rt.streamWaitEvent(main, events[k + 1], 0)
