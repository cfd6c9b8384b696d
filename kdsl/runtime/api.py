"""Public names of the runtime (arrays, devices, streams, launch, Tape)."""

from kdsl.runtime import context
from kdsl.runtime.alloc import (
    clone,
    copy,
    empty,
    empty_like,
    from_numpy,
    full,
    full_like,
    ones,
    ones_like,
    zeros,
    zeros_like,
)
from kdsl.runtime.array import array, array1d, array2d, array3d, array4d
from kdsl.runtime.context import init
from kdsl.runtime.device import (
    Device,
    ScopedDevice,
    get_cuda_device_count,
    get_cuda_devices,
    get_device,
    get_preferred_device,
    is_cuda_available,
    set_device,
)
from kdsl.runtime.indexed import (
    indexedarray,
    indexedarray1d,
    indexedarray2d,
    indexedarray3d,
    indexedarray4d,
)
from kdsl.runtime.launch import Launch, default_backend_for, launch
from kdsl.runtime.stream import (
    Event,
    ScopedStream,
    Stream,
    get_event_elapsed_time,
    get_stream,
    record_event,
    set_stream,
    synchronize,
    synchronize_device,
    synchronize_event,
    synchronize_stream,
    wait_event,
    wait_stream,
)
from kdsl.runtime.structs import Struct, struct
from kdsl.runtime.tape import Tape

__all__ = [
    "Device", "Event", "Launch", "ScopedDevice", "ScopedStream", "Stream", "Struct", "Tape",
    "array", "array1d",
    "array2d", "array3d", "array4d", "clone", "context", "copy", "default_backend_for", "empty",
    "empty_like", "from_numpy", "full", "full_like", "get_cuda_device_count",
    "get_cuda_devices", "get_device", "get_event_elapsed_time", "get_preferred_device",
    "get_stream", "indexedarray", "indexedarray1d", "indexedarray2d", "indexedarray3d",
    "indexedarray4d", "init", "is_cuda_available", "launch", "ones", "ones_like", "record_event",
    "set_device", "set_stream", "struct", "synchronize", "synchronize_device", "synchronize_event",
    "synchronize_stream", "wait_event", "wait_stream", "zeros", "zeros_like",
]  # fmt: skip
