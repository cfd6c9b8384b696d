"""``IntsReader``: a few int32 of a device array read back without waiting for later work.

A mesh's construction checks its indices and points on the device and must raise
there, before it returns, when they are bad. Reading the check's answer with
``array.numpy()`` waits for the whole stream and, placed before the BVH build, keeps
the host from issuing that build until the check is done. ``start`` instead enqueues a
copy of the values into pinned host memory and an event behind it on the stream; the
caller issues more work (the BVH build), and ``values`` then waits for the event only:
the check and the copy, long done by then, not the build. The copy runs on a side stream that waits for the work issued so far (an
event), not on the device's stream: the kernels issued after ``start`` do not queue
behind a device-to-host copy (a copy between two kernels of one stream cost the H200
a few microseconds of switching; session 12, docs/performance.md). On the CPU the
launches have run when they return, so ``start`` reads the values at once.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from kdsl.errors import KdslRuntimeError
from kdsl.runtime.array import array
from kdsl.runtime.device import cuda_device_count, cupy
from kdsl.runtime.graphs import state as graphs
from kdsl.runtime.stream import current_stream


class IntsReader:
    """Reads ``source`` (a contiguous 1-d int32 array, a few elements) back to the host:
    ``start()`` enqueues the read behind the work issued so far on the device's current
    stream, ``values()`` waits for it and returns the values as a tuple of ints. A
    pinned buffer, a side stream and two events are made once per reader. The copy runs
    beside the work issued after ``start``, so that work must not write ``source``
    before ``values()`` returns (a mesh's check counters are written again only after
    the host has its answers)."""

    __slots__ = ("_device", "_event", "_host", "_issued", "_nbytes", "_pinned", "_ptr", "_side",
                 "_source", "_values")  # fmt: skip

    def __init__(self, source: array) -> None:
        self._device = source.device
        self._source = source
        self._values: tuple[int, ...] = ()
        self._nbytes = 4 * source.shape[0]
        if self._device.is_cpu:
            return
        cp = cupy()
        self._ptr = source.ptr
        self._pinned = cp.cuda.alloc_pinned_memory(max(self._nbytes, 4))
        self._host = np.frombuffer(self._pinned, np.int32, source.shape[0])
        with cp.cuda.Device(self._device.ordinal):
            self._issued = cp.cuda.Event(block=False, disable_timing=True)  # on the stream
            self._event = cp.cuda.Event(block=False, disable_timing=True)  # the copy's end
            self._side = cp.cuda.Stream(non_blocking=True)

    def start(self) -> None:
        """Enqueue the read behind the work issued so far on the device's stream (refused
        while a graph capture is open there: the values do not exist before replay)."""
        if graphs.ACTIVE:
            graphs.refuse_host_read(self._device, "a check's read back")
        if self._device.is_cpu:
            self._values = tuple(self._source.numpy().tolist())
            return
        rt = cupy().cuda.runtime
        raw = current_stream(self._device).cuda_stream
        args = (self._host.ctypes.data, self._ptr, self._nbytes, raw, self._issued.ptr,
                self._side.ptr, self._event.ptr)  # fmt: skip
        if cuda_device_count() == 1:
            _enqueue(rt, *args)
            return
        current = rt.getDevice()
        rt.setDevice(self._device.ordinal)
        try:
            _enqueue(rt, *args)
        finally:
            rt.setDevice(current)

    def copy_on(self, stream: Any) -> None:
        """Enqueue the read on ``stream`` (a ``kdsl.Stream`` of the device already behind
        the work that writes ``source``: a branch of ``ForkedSteps``), as ``start``
        does. Inside a graph capture of that stream the event ``values`` waits for is
        recorded as a node of the graph (an external event record), so every replay of
        the graph records it: the host then waits for the copy, not for the graph."""
        if self._device.is_cpu:
            self._values = tuple(self._source.numpy().tolist())
            return
        rt = cupy().cuda.runtime
        raw = stream.cuda_stream
        rt.memcpyAsync(self._host.ctypes.data, self._ptr, self._nbytes, rt.memcpyDeviceToHost,
                       raw)  # fmt: skip
        if stream.is_capturing:
            _record_external(self._event.ptr, raw)
        else:
            rt.eventRecord(self._event.ptr, raw)

    def values(self) -> tuple[int, ...]:
        """The values as of ``start`` (waiting for the read on a GPU)."""
        if self._device.is_cpu:
            return self._values
        cupy().cuda.runtime.eventSynchronize(self._event.ptr)
        return tuple(self._host.tolist())


def _enqueue(rt: Any, host: int, ptr: int, nbytes: int, stream: int, issued: int, side: int,
             done: int) -> None:  # fmt: skip
    """The copy of ``nbytes`` at ``ptr`` into ``host`` on ``side`` behind the work issued
    on ``stream`` so far, then ``done`` recorded on ``side``."""
    rt.eventRecord(issued, stream)
    rt.streamWaitEvent(side, issued, 0)
    rt.memcpyAsync(host, ptr, nbytes, rt.memcpyDeviceToHost, side)
    rt.eventRecord(done, side)


#: The driver's ``cuEventRecordWithFlags`` (ctypes), loaded on first use.
_RECORD: list = []


def _record_external(event: int, stream: int) -> None:
    """Record ``event`` on the capturing ``stream`` as an event node of the graph
    (``CU_EVENT_RECORD_EXTERNAL``; CuPy has no binding for it). A failure raises, which
    ends the capture: the caller's steps then run without a graph."""
    if not _RECORD:
        import ctypes

        fn = ctypes.CDLL("libcuda.so.1").cuEventRecordWithFlags
        fn.argtypes, fn.restype = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_uint], ctypes.c_int
        _RECORD.append(fn)
    err = _RECORD[0](event, stream, 1)
    if err:
        raise KdslRuntimeError(f"cuEventRecordWithFlags failed in a graph capture (CUresult {err})")
