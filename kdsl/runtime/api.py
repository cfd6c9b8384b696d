"""Public names of the runtime (arrays, devices, streams, launch, Tape)."""

from kdsl.frontend.builtins import register_host_alias
from kdsl.frontend.builtins_arrays import ARRAY_FROM_PTR
from kdsl.frontend.builtins_local import LOCAL_ZEROS
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
from kdsl.runtime.array import array, array1d, array2d, array3d, array4d, from_ptr
from kdsl.runtime.context import init
from kdsl.runtime.device import (
    Device,
    ScopedDevice,
    get_cuda_device,
    get_cuda_device_count,
    get_cuda_devices,
    get_device,
    get_devices,
    get_preferred_device,
    is_cpu_available,
    is_cuda_available,
    is_device_available,
    set_device,
)
from kdsl.runtime.fixedarray import fixedarray
from kdsl.runtime.graphs.capture import (
    CaptureMode,
    ScopedCapture,
    capture_begin,
    capture_end,
    capture_if,
    capture_launch,
    capture_load,
    capture_load_from_bytes,
    capture_save,
    capture_while,
    is_conditional_graph_supported,
)
from kdsl.runtime.graphs.graph import Graph
from kdsl.runtime.indexed import (
    indexedarray,
    indexedarray1d,
    indexedarray2d,
    indexedarray3d,
    indexedarray4d,
)
from kdsl.runtime.ipc import event_from_ipc_handle, from_ipc_handle
from kdsl.runtime.launch import Launch, default_backend_for, launch
from kdsl.runtime.logger import (
    LOG_DEBUG,
    LOG_ERROR,
    LOG_INFO,
    LOG_WARNING,
    Logger,
    ScopedLogger,
    ScopedLogLevel,
    get_logger,
    set_logger,
)
from kdsl.runtime.mempool import (
    ScopedMempool,
    get_mempool_release_threshold,
    get_mempool_used_mem_current,
    get_mempool_used_mem_high,
    is_mempool_enabled,
    is_mempool_supported,
    set_mempool_enabled,
    set_mempool_release_threshold,
)
from kdsl.runtime.modules import (
    Module,
    clear_kernel_cache,
    force_load,
    get_module,
    get_module_options,
    load_module,
    set_module_options,
)
from kdsl.runtime.peer import (
    ScopedMempoolAccess,
    ScopedPeerAccess,
    is_mempool_access_enabled,
    is_mempool_access_supported,
    is_peer_access_enabled,
    is_peer_access_supported,
    set_mempool_access_enabled,
    set_peer_access_enabled,
)
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
from kdsl.runtime.timing import (
    TIMING_ALL,
    TIMING_GRAPH,
    TIMING_KERNEL,
    TIMING_KERNEL_BUILTIN,
    TIMING_MEMCPY,
    TIMING_MEMSET,
    ScopedTimer,
    TimingResult,
    timing_begin,
    timing_end,
    timing_print,
)

__all__ = [
    "Device", "Event", "Launch", "ScopedDevice", "ScopedStream", "Stream", "Struct", "Tape",
    "array", "array1d",
    "array2d", "array3d", "array4d", "clone", "context", "copy", "default_backend_for", "empty",
    "empty_like", "from_numpy", "from_ptr", "full", "full_like", "get_cuda_device_count",
    "get_cuda_devices", "get_device", "get_event_elapsed_time", "get_preferred_device",
    "get_stream", "indexedarray", "indexedarray1d", "indexedarray2d", "indexedarray3d",
    "indexedarray4d", "init", "is_cuda_available", "launch", "ones", "ones_like", "record_event",
    "set_device", "set_stream", "struct", "synchronize", "synchronize_device", "synchronize_event",
    "synchronize_stream", "wait_event", "wait_stream", "zeros", "zeros_like",
    # modules, timing, logging, devices and memory pools (issue 14, item 6)
    "LOG_DEBUG", "LOG_ERROR", "LOG_INFO", "LOG_WARNING", "Logger", "Module", "ScopedLogLevel",
    "ScopedLogger", "ScopedMempool", "ScopedTimer", "TIMING_ALL", "TIMING_GRAPH", "TIMING_KERNEL",
    "TIMING_KERNEL_BUILTIN", "TIMING_MEMCPY", "TIMING_MEMSET", "TimingResult",
    "clear_kernel_cache", "force_load", "get_cuda_device", "get_devices", "get_logger",
    "get_mempool_release_threshold", "get_mempool_used_mem_current", "get_mempool_used_mem_high",
    "get_module", "get_module_options", "is_cpu_available", "is_device_available",
    "is_mempool_enabled", "is_mempool_supported", "load_module", "set_logger",
    "set_mempool_enabled", "set_mempool_release_threshold", "set_module_options",
    "timing_begin", "timing_end", "timing_print",
    # graphs (issue 17, item 1)
    "CaptureMode", "Graph", "ScopedCapture", "capture_begin", "capture_end", "capture_if",
    "capture_launch", "capture_load", "capture_load_from_bytes", "capture_save", "capture_while",
    "is_conditional_graph_supported",
    # several GPUs in one process (issue 19, item 1)
    "ScopedMempoolAccess", "ScopedPeerAccess", "is_mempool_access_enabled",
    "is_mempool_access_supported", "is_peer_access_enabled", "is_peer_access_supported",
    "set_mempool_access_enabled", "set_peer_access_enabled", "event_from_ipc_handle",
    "from_ipc_handle",
    # thread-local arrays in kernels (issue 14)
    "fixedarray",
]  # fmt: skip

# In kernels, ``zeros(shape, dtype)`` makes a thread-local array (Warp's fixedarray).
register_host_alias(zeros, LOCAL_ZEROS)
# ``array(ptr=..., shape=..., dtype=...)`` wraps memory at an address (Warp's builtin).
register_host_alias(array, ARRAY_FROM_PTR)
