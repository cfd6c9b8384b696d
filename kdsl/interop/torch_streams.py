"""Ordering kdsl's CUDA stream with PyTorch's current stream, cheaply.

A tensor shared between kdsl and PyTorch is safe when the side that reads it runs
after the work the other side enqueued. Two cases need no CUDA call at all:

- both sides use the same stream (``stream_from_torch``, ``stream_to_torch``);
- PyTorch's current stream is the legacy default stream (handle 0, what PyTorch
  uses unless told otherwise) and kdsl's is a *blocking* stream that kdsl created
  (its default): CUDA itself orders the legacy default stream with every blocking
  stream of the context, in both directions.

Only otherwise (a side stream, a non-blocking or wrapped kdsl stream, PyTorch's
per-thread default stream) does the waiting side need an event. ``needs_wait``
tells the cases apart from PyTorch's raw current-stream handle, which
``raw_stream`` reads through the C function PyTorch's own compiler uses
(``torch._C._cuda_getCurrentRawStream``, well under a microsecond), falling back to
the public ``torch.cuda.current_stream(i).cuda_stream`` (a few microseconds) where a
build lacks it.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

from kdsl.runtime.device import Device, cupy
from kdsl.runtime.stream import Stream, current_stream

#: The legacy default stream's handle.
LEGACY = 0


@functools.cache
def raw_stream_reader(torch: Any) -> Callable[[int], int]:
    """``f(ordinal)``: PyTorch's current ``cudaStream_t`` on a GPU, as an int (built once)."""
    fast = getattr(torch._C, "_cuda_getCurrentRawStream", None)
    if fast is not None:
        return lambda ordinal: int(fast(ordinal))
    return lambda ordinal: int(torch.cuda.current_stream(ordinal).cuda_stream)


def implicitly_ordered(stream: Stream, torch_raw: int) -> bool:
    """True when kdsl ``stream`` and the torch stream ``torch_raw`` need no event between them."""
    if torch_raw == stream.cuda_stream:
        return True
    if torch_raw != LEGACY:
        return False
    # A wrapped handle (ExternalStream) may be non-blocking whatever CuPy reports.
    return isinstance(stream.cupy, cupy().cuda.Stream) and stream.is_blocking


def needs_wait(device: Device, torch_raw: int) -> Stream | None:
    """kdsl's current stream on ``device`` when it and ``torch_raw`` need an event, else None."""
    stream = current_stream(device)
    return None if implicitly_ordered(stream, torch_raw) else stream


def torch_waits_for_kdsl(device: Device, torch_raw: int) -> None:
    """Make PyTorch's stream ``torch_raw`` wait for the work enqueued on kdsl's stream."""
    stream = needs_wait(device, torch_raw)
    if stream is not None:
        Stream(device, cuda_stream=torch_raw).wait_stream(stream)


def kdsl_waits_for_torch(device: Device, torch_raw: int) -> None:
    """Make kdsl's current stream wait for the work enqueued on PyTorch's stream ``torch_raw``."""
    stream = needs_wait(device, torch_raw)
    if stream is not None:
        stream.wait_stream(Stream(device, cuda_stream=torch_raw))
