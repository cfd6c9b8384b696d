"""Public names of interoperability (star-imported by ``kdsl``).

``from_numpy``, ``dtype_to_numpy`` and ``dtype_from_numpy`` come from the runtime
and ``kdsl.types``; everything here imports its framework only when called.
"""

from kdsl.interop import dlpack
from kdsl.interop.dlpack import from_dlpack, to_dlpack
from kdsl.interop.jax import (
    device_from_jax,
    device_to_jax,
    dtype_from_jax,
    dtype_to_jax,
    from_jax,
    to_jax,
)
from kdsl.interop.jax_callable import jax_callable
from kdsl.interop.jax_kernel import jax_kernel
from kdsl.interop.paddle import (
    device_from_paddle,
    device_to_paddle,
    dtype_from_paddle,
    dtype_to_paddle,
    from_paddle,
    stream_from_paddle,
    to_paddle,
)
from kdsl.interop.torch import (
    device_from_torch,
    device_to_torch,
    dtype_from_torch,
    dtype_to_torch,
    from_torch,
    stream_from_torch,
    stream_to_torch,
    to_torch,
)
from kdsl.runtime.descriptor import ArrayDescriptor

__all__ = [
    "ArrayDescriptor", "device_from_jax", "device_from_paddle", "device_from_torch",
    "device_to_jax", "device_to_paddle", "device_to_torch", "dtype_from_jax",
    "dtype_from_paddle", "dtype_from_torch", "dtype_to_jax", "dtype_to_paddle",
    "dtype_to_torch", "from_dlpack", "from_jax", "from_paddle", "from_torch", "jax_callable",
    "jax_kernel",
    "stream_from_paddle", "stream_from_torch", "stream_to_torch", "to_dlpack", "to_jax",
    "to_paddle", "to_torch",
]  # fmt: skip

# isort: split
# The runtime reaches the code above only through its adapter registry (it sits below).
from kdsl.interop.foreign import cached_buffer, foreign_buffer
from kdsl.interop.jax import tracer_message_or_none
from kdsl.runtime.adapters import register_adapter

register_adapter("foreign_buffer", foreign_buffer)
register_adapter("cached_buffer", cached_buffer)
register_adapter("tracer_message", tracer_message_or_none)
register_adapter("dlpack_export", dlpack.export)
