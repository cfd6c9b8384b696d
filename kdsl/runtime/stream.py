"""CUDA streams and events, and the synchronization functions (Warp's API).

Every CUDA device has a *current* stream, created lazily by ``get_stream``:
kernel launches, copies and the CuPy work behind array methods are enqueued on
it, so they run in the order Python issued them without any synchronization.
kdsl never uses the legacy default stream (handle 0) itself; its streams are
created *blocking* (CUDA's default flag), so work that other libraries put on
the legacy default stream (plain CuPy or PyTorch code) is still ordered with
kdsl's. ``Stream(device, blocking=False)`` makes a stream that is not.

The host waits only where data comes back to it (``array.numpy()``, reading one
element, ``list()``, ``repr``) or where asked to (``synchronize*``). On the CPU
all work is synchronous: ``synchronize()`` and ``synchronize_device("cpu")`` are
no-ops, while asking for a stream or event of the CPU is an error, as in Warp.
"""

from __future__ import annotations

from typing import Any

from kdsl.errors import KdslError
from kdsl.runtime.device import (
    Device,
    ScopedDevice,
    cuda_device_count,
    cuda_initialized,
    cupy,
    get_device,
)
from kdsl.runtime.graphs.state import refuse_sync

_current: dict[int, Stream] = {}  # device ordinal -> its current stream
_used: set[int] = set()  # ordinals that have had a kdsl stream (what synchronize() waits for)


def _cuda_device(device: Any, what: str) -> Device:
    dev = get_device(device)
    if not dev.is_cuda:
        raise KdslError(
            f"{what} needs a CUDA device, but '{dev}' is not one (CPU work is synchronous "
            f"and has no streams or events)"
        )
    return dev


class _CudaWork:
    """What a ``Stream`` and an ``Event`` share: a CuPy stream or event (``.cupy``) of a device.

    Their work is what was enqueued on the stream so far, or what came before the
    event's last record.
    """

    cupy: Any
    device: Device

    @property
    def is_complete(self) -> bool:
        """True when the stream's (or event's) work has finished."""
        return bool(self.cupy.done)

    def synchronize(self) -> None:
        """Block the host until the stream's (or event's) work has finished."""
        refuse_sync(f"{type(self).__name__}.synchronize()")
        self.cupy.synchronize()


class Stream(_CudaWork):
    """A CUDA stream on one device.

    ``Stream(device=None, priority=0, cuda_stream=None, blocking=True)`` creates a
    new stream, or wraps an existing ``cudaStream_t`` given as ``cuda_stream`` (an
    int; kdsl does not destroy it). ``.cuda_stream`` is the raw handle, ``.cupy``
    the ``cupy.cuda.Stream``; ``with stream.cupy:`` makes CuPy enqueue on it.
    """

    def __init__(
        self,
        device: Any = None,
        priority: int = 0,
        cuda_stream: int | None = None,
        blocking: bool = True,
    ) -> None:
        dev = _cuda_device(device, "Stream()")
        cp = cupy()
        with cp.cuda.Device(dev.ordinal):
            if cuda_stream is not None:
                self.cupy = cp.cuda.ExternalStream(int(cuda_stream), dev.ordinal)
            else:
                self.cupy = cp.cuda.Stream(non_blocking=not blocking, priority=priority)
        self.device = dev
        self._event: Event | None = None  # reused by wait_stream
        _used.add(dev.ordinal)

    @property
    def cuda_stream(self) -> int:
        """The raw ``cudaStream_t`` handle as an int."""
        return int(self.cupy.ptr)

    @property
    def priority(self) -> int:
        """The stream's priority (lower numbers run first)."""
        return int(self.cupy.priority)

    @property
    def is_capturing(self) -> bool:
        """True while a graph capture (kdsl's or another library's) is open on the stream."""
        return bool(self.cupy.is_capturing())

    @property
    def is_blocking(self) -> bool:
        """True when the stream synchronizes with the legacy default stream."""
        return not self.cupy.is_non_blocking

    def record_event(self, event: Event | None = None) -> Event:
        """Record ``event`` (a new one when None) at this point of the stream; returns it."""
        if event is None:
            event = Event(self.device)
        elif event.device != self.device:
            raise KdslError(
                f"an event of '{event.device}' cannot be recorded on a stream of '{self.device}'"
            )
        with cupy().cuda.Device(self.device.ordinal):
            event.cupy.record(self.cupy)
        return event

    def wait_event(self, event: Event) -> None:
        """Make later work on this stream wait until ``event`` (any device's) completes."""
        with cupy().cuda.Device(self.device.ordinal):
            self.cupy.wait_event(event.cupy)

    def wait_stream(self, other_stream: Stream, event: Event | None = None) -> None:
        """Make later work on this stream wait for all work enqueued on ``other_stream``."""
        if other_stream is self:
            return
        if event is None:
            # Waiting captures the event's state at call time, so one cached event suffices.
            if other_stream._event is None:
                other_stream._event = Event(other_stream.device)
            event = other_stream._event
        self.wait_event(other_stream.record_event(event))

    def __cuda_stream__(self) -> tuple[int, int]:
        # The CUDA stream protocol (cuda.core, CuPy, PyTorch read it).
        return (0, self.cuda_stream)

    def __eq__(self, other: object) -> bool:
        if isinstance(other, Stream):
            return self.cuda_stream == other.cuda_stream and self.device == other.device
        return NotImplemented

    def __hash__(self) -> int:
        return hash((self.cuda_stream, self.device.alias))

    def __repr__(self) -> str:
        return f"Stream(device='{self.device}', cuda_stream={self.cuda_stream:#x})"


class Event(_CudaWork):
    """A CUDA event on one device; ``enable_timing=True`` allows ``get_event_elapsed_time``."""

    def __init__(
        self,
        device: Any = None,
        cuda_event: int | None = None,
        enable_timing: bool = False,
        interprocess: bool = False,
    ) -> None:
        dev = _cuda_device(device, "Event()")
        if cuda_event is not None:
            raise KdslError(
                "Event(cuda_event=...): wrapping an external CUDA event is not supported"
            )
        if interprocess and enable_timing:
            raise KdslError("an interprocess event cannot have timing enabled")
        cp = cupy()
        with cp.cuda.Device(dev.ordinal):
            self.cupy = cp.cuda.Event(disable_timing=not enable_timing, interprocess=interprocess)
        self.device = dev
        self.enable_timing = enable_timing
        self.interprocess = interprocess

    def ipc_handle(self) -> bytes:
        """The CUDA IPC handle of an ``Event(interprocess=True)``, for
        ``event_from_ipc_handle`` in another process."""
        from kdsl.runtime.ipc import event_ipc_handle  # ipc wraps events: imported late

        return event_ipc_handle(self)

    @property
    def cuda_event(self) -> int:
        """The raw ``cudaEvent_t`` handle as an int."""
        return int(self.cupy.ptr)

    def record(self, stream: Stream | None = None) -> Event:
        """Record this event on ``stream`` (the device's current stream when None)."""
        return (stream or get_stream(self.device)).record_event(self)

    def __repr__(self) -> str:
        return f"Event(device='{self.device}', enable_timing={self.enable_timing})"


def get_stream(device: Any = None) -> Stream:
    """The current stream of ``device`` (the default device when None); created on first use."""
    dev = _cuda_device(device, "get_stream()")
    s = _current.get(dev.ordinal)
    if s is None:
        s = _current[dev.ordinal] = Stream(dev)
    return s


def current_stream(device: Device) -> Stream:
    """``get_stream`` of a CUDA ``Device`` object (the launch path's): a dict lookup once
    the stream exists."""
    s = _current.get(device.ordinal)
    return s if s is not None else get_stream(device)


def set_stream(stream: Stream, device: Any = None, sync: bool = False) -> None:
    """Make ``stream`` its device's current stream; ``sync`` first makes it wait for the old one."""
    if not isinstance(stream, Stream):
        raise KdslError(f"set_stream() takes a kdsl.Stream, not {type(stream).__name__}")
    if device is not None and get_device(device) != stream.device:
        raise KdslError(
            f"set_stream(): the stream is on '{stream.device}', not on '{get_device(device)}'"
        )
    if sync:
        stream.wait_stream(get_stream(stream.device))
    _current[stream.device.ordinal] = stream


class ScopedStream:
    """``with ScopedStream(s):`` makes ``s`` its device's current stream and the device default.

    ``sync_enter`` makes ``s`` wait for the previous stream's work first;
    ``sync_exit`` makes the previous stream wait for ``s``'s work on exit.
    ``ScopedStream(None)`` does nothing.
    """

    def __init__(self, stream: Stream | None, sync_enter: bool = True, sync_exit: bool = False):
        self.stream = stream
        self.sync_enter = sync_enter
        self.sync_exit = sync_exit
        self.device = stream.device if stream is not None else None

    def __enter__(self) -> Stream | None:
        if self.stream is None:
            return None
        self._scope = ScopedDevice(self.stream.device)
        self._scope.__enter__()
        self.saved_stream = get_stream(self.stream.device)
        set_stream(self.stream, sync=self.sync_enter)
        return self.stream

    def __exit__(self, *exc_info: object) -> None:
        if self.stream is None:
            return
        if self.sync_exit:
            self.saved_stream.wait_stream(self.stream)
        set_stream(self.saved_stream)
        self._scope.__exit__(*exc_info)


def record_event(event: Event | None = None) -> Event:
    """Record ``event`` (a new one when None) on the default device's current stream."""
    return get_stream().record_event(event)


def wait_event(event: Event) -> None:
    """Make the default device's current stream wait for ``event``."""
    get_stream().wait_event(event)


def wait_stream(other_stream: Stream, event: Event | None = None) -> None:
    """Make the default device's current stream wait for the work on ``other_stream``."""
    get_stream().wait_stream(other_stream, event)


def get_event_elapsed_time(start_event: Event, end_event: Event, synchronize: bool = True) -> float:
    """Milliseconds between two recorded timing events (waits for ``end_event`` by default)."""
    for e in (start_event, end_event):
        if not e.enable_timing:
            raise KdslError("get_event_elapsed_time() needs events made with enable_timing=True")
    if synchronize:
        end_event.synchronize()
    return float(cupy().cuda.get_elapsed_time(start_event.cupy, end_event.cupy))


def synchronize() -> None:
    """Block the host until all work kdsl enqueued on every device has finished."""
    refuse_sync("synchronize()")
    if not cuda_initialized():
        return  # without CuPy loaded nothing can be pending
    cp = cupy()
    for ordinal in sorted(_used):
        if ordinal < cuda_device_count():
            with cp.cuda.Device(ordinal) as d:
                d.synchronize()
    _release_pools()


def _release_pools() -> None:
    from kdsl.runtime import mempool

    if mempool.THRESHOLDS:
        mempool.trim_all()


def synchronize_device(device: Any = None) -> None:
    """Block the host until all work on ``device`` has finished (a no-op for the CPU)."""
    dev = get_device(device)
    refuse_sync("synchronize_device()")
    if dev.is_cuda:
        with cupy().cuda.Device(dev.ordinal) as d:
            d.synchronize()
        _release_pools()


def synchronize_stream(stream_or_device: Any = None) -> None:
    """Block the host until a stream's work (or a device's current stream's) has finished."""
    s = stream_or_device if isinstance(stream_or_device, Stream) else get_stream(stream_or_device)
    s.synchronize()


def synchronize_event(event: Event) -> None:
    """Block the host until ``event`` has completed."""
    event.synchronize()
