"""Which captures are open, and the checks the rest of the runtime asks of them.

Imported by launch, streams, memory and allocation code (so it imports nothing of
the runtime): they ask ``recording`` whether work on a device and stream is being
captured, and call ``refuse_host_read`` / ``refuse_sync`` before doing something a
capture cannot hold, so the error comes before the driver invalidates the capture
and the stream stays usable.
"""

from __future__ import annotations

from typing import Any

from kdsl.errors import KdslRuntimeError

#: The open recordings, innermost last (empty when nothing is captured: launch tests it).
ACTIVE: list[Any] = []


def recording(device: Any, stream: Any) -> Any:
    """The open recording that work on ``device`` (and CUDA ``stream``) goes to, or None."""
    for rec in reversed(ACTIVE):
        if rec.device == device and (device.is_cpu or rec.stream is stream or (
            stream is not None and rec.stream == stream
        )):  # fmt: skip
            return rec
    return None


def on_device(device: Any) -> Any:
    """The innermost open recording on ``device`` (any stream), or None."""
    for rec in reversed(ACTIVE):
        if rec.device == device:
            return rec
    return None


def refuse_host_read(device: Any, what: str) -> None:
    """Raise if ``device`` is being captured: its data is not computed until replay."""
    if ACTIVE and on_device(device) is not None:
        raise KdslRuntimeError(
            f"{what} while a graph capture is open on '{device}': captured work runs only "
            f"when the graph is launched, and a capture cannot hold a host read. Read the "
            f"data after capture_end() and capture_launch()"
        )


def refuse_sync(what: str) -> None:
    """Raise if any capture is open: a host synchronization cannot be captured."""
    if ACTIVE:
        rec = ACTIVE[-1]
        raise KdslRuntimeError(
            f"{what} while a graph capture is open on '{rec.device}': a host "
            f"synchronization cannot be part of a graph. Synchronize after capture_end()"
        )


def cpu_recording(device: Any) -> Any:
    """The open CPU capture when ``device`` is the CPU (host work must be recorded), or None."""
    if ACTIVE and device.is_cpu:
        return on_device(device)
    return None


def refuse_upload(device: Any, what: str) -> None:
    """Raise if ``device`` is being captured: CUDA graphs cannot hold pageable host memory."""
    if ACTIVE and device.is_cuda and on_device(device) is not None:
        raise KdslRuntimeError(
            f"{what} while a graph capture is open on '{device}': a copy between NumPy "
            f"(pageable host) memory and the device cannot be captured. Copy before "
            f"capture_begin() or after capture_end()"
        )


def run_or_record(plan: Any, dims: tuple, converted: list, stream: Any) -> None:
    """Launch ``plan`` now, or record it when a capture is open on its device and stream."""
    rec = recording(plan.device, stream) if ACTIVE else None
    if rec is None:
        plan.backend.launch(plan.compiled, dims, converted, stream)
    else:
        rec.record_launch(plan, dims, converted, stream)


def captured_fill(buf: Any, device: Any, value: Any, fresh: bool = False) -> None:
    """Fill ``buf`` with ``value`` (a NumPy value; None: leave it) under an open capture.

    On the CPU the fill is recorded for every replay (and runs now too when ``buf`` is
    ``fresh``: just allocated, so owned by the graph). On CUDA a uniform value becomes CuPy's
    fill kernel on the capturing stream (an upload from the host could not be
    captured); the caller holds ``mem.scope(device)``.
    """
    rec = on_device(device)
    if rec is None:  # a capture on another device: fill as usual
        if value is not None:
            buf[...] = value if device.is_cpu else _cupy_array(value)
        return
    if device.is_cpu:
        if fresh:  # new memory: valid now too (an existing array changes only at replay)
            rec.own(buf)
            if value is not None:
                buf[...] = value
        if value is not None:
            rec.record_host(_setter(value.copy()), buf)
        return
    if value is None:
        return
    flat = value.reshape(-1)
    if flat.size and not (flat == flat[0]).all():
        raise KdslRuntimeError(
            f"filling an array with the non-uniform value {value.tolist()} while a graph "
            f"capture is open on '{device}' would upload it from the host, which a capture "
            f"cannot hold; fill it before capture_begin() or write it with a kernel"
        )
    buf.fill(flat[0] if flat.size else 0)


def _cupy_array(value: Any) -> Any:
    import cupy

    return cupy.asarray(value)


def _setter(value: Any) -> Any:
    def fill(buf: Any) -> None:
        buf[...] = value

    return fill


def copy_rows(dest_offset: int, src_offset: int, count: int, inner: tuple) -> Any:
    """A CPU copy of ``count`` elements between two buffers, row-major (a recorded copy)."""

    def copy(dest: Any, src: Any) -> None:
        rows = src.reshape(-1, *inner)[src_offset : src_offset + count]
        flat = dest.reshape(-1, *inner)
        flat[dest_offset : dest_offset + count] = rows
        if not _shares(flat, dest):  # a strided destination: reshape made a copy
            dest[...] = flat.reshape(dest.shape)

    return copy


def _shares(a: Any, b: Any) -> bool:
    import numpy as np

    return bool(np.shares_memory(a, b))


def record_assign(dest: Any, src: Any) -> bool:
    """Record ``dest.assign(src)`` in an open CPU capture; False when none is open.

    A CPU array source is read at replay; any other source (NumPy data, a list) is
    copied now and that copy is written at each replay.
    """
    import numpy as np

    rec = on_device(dest.device)
    if rec is None:
        return False
    src_dev = getattr(src, "device", None)
    if getattr(src_dev, "is_cpu", False) and hasattr(src, "__kdsl_type__"):
        rec.record_host(_copy_into, dest._buf, src._buf)
    elif src_dev is not None and not getattr(src_dev, "is_cpu", True):
        raise KdslRuntimeError(
            f"assign() from an array on '{src_dev}' while a graph capture is open on 'cpu': "
            f"a CPU graph cannot hold a copy from a device; copy before the capture"
        )
    else:
        data = np.array(src, dtype=dest._buf.dtype)
        rec.record_host(lambda d: _copy_into(d, data), dest._buf)
    return True


def _copy_into(dest: Any, src: Any) -> None:
    import numpy as np

    if src.size == dest.size and src.shape != dest.shape:
        src = src.reshape(dest.shape)
    np.copyto(dest, src, casting="unsafe")
