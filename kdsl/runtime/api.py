"""Public names of the runtime (arrays, devices, launch)."""

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
    get_cuda_device_count,
    get_device,
    get_preferred_device,
    is_cuda_available,
    set_device,
    synchronize,
    synchronize_device,
)
from kdsl.runtime.launch import Launch, default_backend_for, launch

__all__ = [
    "Device", "Launch", "array", "array1d", "array2d", "array3d", "array4d", "clone",
    "context", "copy", "default_backend_for", "empty", "empty_like", "from_numpy", "full",
    "full_like", "get_cuda_device_count", "get_device", "get_preferred_device", "init",
    "is_cuda_available", "launch", "ones", "ones_like", "set_device", "synchronize",
    "synchronize_device", "zeros", "zeros_like",
]  # fmt: skip
