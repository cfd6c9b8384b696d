"""``kdsl.Graph``: a captured sequence of work, replayed by ``capture_launch``.

A graph is a list of nodes run in order:

- on the CPU, a prepared launch (``Backend.prepare``: its arguments converted and
  packed once at capture time) or a recorded copy or fill;
- on a CUDA device, a segment: a CUDA graph (CuPy stream capture, instantiated
  once) holding every launch, copy and fill issued on the stream between two
  conditionals;
- a conditional (``capture_if`` / ``capture_while``), whose branches are graphs and
  whose condition is read on replay (on CUDA: a 4-byte copy and a stream sync).

Memory. A graph keeps what it allocated during the capture alive. Arrays made
before the capture stay the user's: the graph holds their allocations (so a replay
never touches freed memory) but counts who else does, and a replay after the user
dropped every array over one of them raises ``KdslRuntimeError`` naming it, rather
than writing into memory nobody can read any more.
"""

from __future__ import annotations

import ctypes
import sys
from typing import Any

import numpy as np

from kdsl.errors import KdslRuntimeError
from kdsl.runtime.device import Device


def _refcount_of_held(held: list) -> int:
    # The references ``MemoryWatch.check`` itself makes to an object it holds once.
    for obj, _ in held:
        return sys.getrefcount(obj)
    return 0


class MemoryWatch:
    """The allocations a graph uses but does not own, with what to call them in errors."""

    __slots__ = ("held", "seen")

    def __init__(self) -> None:
        self.held: list[tuple[Any, str]] = []
        self.seen: set[int] = set()

    def add(self, owner: Any, what: str) -> None:
        """Hold ``owner`` (a NumPy root array or a CuPy memory object) once."""
        if id(owner) not in self.seen:
            self.seen.add(id(owner))
            self.held.append((owner, what))

    def merge(self, other: MemoryWatch) -> None:
        """Also watch what ``other`` watches (a graph replayed inside this one)."""
        for owner, what in other.held:
            self.add(owner, what)

    def check(self) -> None:
        """Raise if an allocation is referenced by nothing but this graph."""
        for owner, what in self.held:
            if sys.getrefcount(owner) <= _ONLY_US:
                raise KdslRuntimeError(
                    f"the graph uses {what}, which was freed after the capture (no array "
                    f"refers to its memory any more). Keep the arrays a graph uses alive "
                    f"while you launch it, or capture again"
                )


def _calibrate() -> int:
    probe = MemoryWatch()
    probe.add(object(), "")
    # Counted the way ``check`` counts: the list entry, the loop variable, the argument.
    for owner, _ in probe.held:
        return sys.getrefcount(owner)
    return 0


_ONLY_US = _calibrate()


def numpy_root(buf: np.ndarray) -> np.ndarray:
    """The NumPy array that owns ``buf``'s memory (``buf`` itself if it does)."""
    root = buf
    while isinstance(root.base, np.ndarray):
        root = root.base
    return root


def detached(buf: np.ndarray) -> np.ndarray:
    """A view of ``buf``'s memory that does not keep it alive (the graph holds the owner)."""
    if buf.size == 0:
        return buf
    lo = sum((n - 1) * s for n, s in zip(buf.shape, buf.strides) if s < 0)
    hi = sum((n - 1) * s for n, s in zip(buf.shape, buf.strides) if s > 0) + buf.itemsize
    addr = buf.__array_interface__["data"][0]
    raw = (ctypes.c_char * (hi - lo)).from_address(addr + lo)
    return np.ndarray(buf.shape, buf.dtype, buffer=raw, offset=-lo, strides=buf.strides)


class Graph:
    """A captured graph of kdsl work on one device; launch it with ``capture_launch``.

    Returned by ``capture_end`` (and ``ScopedCapture.graph``). ``device`` is where it
    runs; ``num_nodes`` counts its replay steps (a CUDA segment counts once).
    """

    def __init__(self, device: Device) -> None:
        self.device = device
        self.nodes: list[Any] = []
        self.watch = MemoryWatch()
        #: Allocations made during the capture (owned: freed with the graph).
        self.owned: list[Any] = []
        #: Graphs replayed inside this one and the branches of its conditionals.
        self.children: list[Graph] = []
        self.is_loaded = False
        self._ended = False

    @property
    def num_nodes(self) -> int:
        """How many replay steps the graph has."""
        return len(self.nodes)

    def replay(self, stream: Any) -> None:
        """Run every node in order (``stream``: the CUDA stream, None on the CPU)."""
        self.watch.check()
        for node in self.nodes:
            node(stream)

    def __repr__(self) -> str:
        return f"Graph(device='{self.device}', nodes={len(self.nodes)})"


def call_node(fn: Any) -> Any:
    """A CPU node running ``fn()`` (a prepared launch, a copy, a fill)."""

    def node(stream: Any) -> None:
        fn()

    node.fn = fn  # type: ignore[attr-defined]
    return node


def segment_node(cupy_graph: Any, ordinal: int) -> Any:
    """A CUDA node launching one instantiated CUDA graph on the replay stream."""
    from kdsl.runtime.device import cupy

    runtime = cupy().cuda.runtime

    def node(stream: Any) -> None:
        if runtime.getDevice() != ordinal:
            with cupy().cuda.Device(ordinal):
                cupy_graph.launch(stream.cupy)
        else:
            cupy_graph.launch(stream.cupy)

    node.cupy_graph = cupy_graph  # type: ignore[attr-defined]
    return node


class ConditionReader:
    """Reads element 0 (an int32) of a condition array on replay."""

    def __init__(self, buf: Any, device: Device) -> None:
        self.device = device
        if device.is_cpu:
            self.view = detached(buf.reshape(-1)[:1])
        else:
            from kdsl.runtime.device import cupy

            cp = cupy()
            self.ptr = int(buf.data.ptr)
            self.pinned = cp.cuda.alloc_pinned_memory(4)
            self.host = np.frombuffer(self.pinned, np.int32, 1)

    def value(self, stream: Any) -> bool:
        """The condition now (on CUDA: after the work enqueued on ``stream`` so far)."""
        if self.device.is_cpu:
            return bool(self.view[0])
        from kdsl.runtime.device import cupy

        rt = cupy().cuda.runtime
        s = stream.cuda_stream
        rt.memcpyAsync(self.host.ctypes.data, self.ptr, 4, rt.memcpyDeviceToHost, s)
        rt.streamSynchronize(s)
        return bool(self.host[0])


def if_node(cond: ConditionReader, on_true: Graph | None, on_false: Graph | None) -> Any:
    """A node running ``on_true`` or ``on_false`` by the condition at replay."""

    def node(stream: Any) -> None:
        branch = on_true if cond.value(stream) else on_false
        if branch is not None:
            branch.replay(stream)

    return node


def while_node(cond: ConditionReader, body: Graph) -> Any:
    """A node replaying ``body`` while the condition holds at replay."""

    def node(stream: Any) -> None:
        while cond.value(stream):
            body.replay(stream)

    return node
