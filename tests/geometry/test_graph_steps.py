"""``kdsl.geometry.graph_steps``: a build's steps replayed as one captured graph. The
capture's failure paths (each leaves no capture open and hands the steps back to be
run one by one), on the CPU's own captures; the replay policy is tested through the
hash grid and lbvh builds (``test_hash_grid_build``, ``test_lbvh_build``), on a GPU
by the cuda tests."""

from __future__ import annotations

import pytest

import kdsl as wp
from kdsl.geometry import graph_steps
from kdsl.runtime.graphs import state


def test_a_capture_that_cannot_begin_runs_nothing():
    ran = []
    assert graph_steps.capture_steps([lambda: ran.append(1)], object()) is None  # not a Stream
    assert ran == [] and state.ACTIVE == []


def test_a_failing_step_ends_the_capture_and_hands_the_steps_back():
    def broken() -> None:
        raise RuntimeError("not capturable")

    with wp.ScopedDevice("cpu"):
        assert graph_steps.capture_steps([broken], None) is None
    assert state.ACTIVE == []


def test_an_interrupt_ends_the_capture_and_goes_on():
    def interrupted() -> None:
        raise KeyboardInterrupt

    with wp.ScopedDevice("cpu"), pytest.raises(KeyboardInterrupt):
        graph_steps.capture_steps([interrupted], None)
    assert state.ACTIVE == []


def test_a_captured_graph_replays():
    calls = []
    with wp.ScopedDevice("cpu"):
        replay = graph_steps.capture_steps([lambda: calls.append("captured")], None)
        assert replay is not None and state.ACTIVE == []
        replay()  # (a host callable is not recorded by the CPU's capture: an empty graph)
    assert calls == ["captured"]


def test_step_graph_runs_one_by_one_when_not_graphed():
    calls = []
    g = graph_steps.StepGraph([lambda: calls.append(1), lambda: calls.append(2)], None, False)
    for _ in range(3):
        g()
    assert calls == [1, 2] * 3 and g.graph is None
