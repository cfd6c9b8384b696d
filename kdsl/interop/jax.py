"""JAX: ``from_jax``, ``to_jax`` and the device and dtype helpers, over DLPack.

JAX arrays are immutable: a kdsl array made by ``from_jax`` shares the JAX
buffer, so a kernel that writes it changes a value JAX believes constant. Use it
for inputs, or for buffers JAX no longer reads. On the CPU, JAX shares a kdsl
buffer (``to_jax``) only when it is 64-byte aligned; otherwise JAX copies it.
A traced value (inside ``jax.jit``) has no data yet and is refused with a clear
error. JAX is imported only when one of these functions runs.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from kdsl.errors import KdslError
from kdsl.interop.dlpack import Exporter, from_dlpack
from kdsl.interop.dtypes import (
    BF16_HINT,
    InteropDeviceError,
    InteropTypeError,
    public_scalar,
    scalar_from_numpy_dtype,
)
from kdsl.interop.frameworks import Framework
from kdsl.ir import types as T
from kdsl.runtime.array import array
from kdsl.runtime.device import Device, get_device

JAX = Framework("JAX", "jax")
_jax = JAX.load


def is_tracer(value: Any) -> bool:
    """True for a JAX tracer (an abstract value inside jit/grad/vmap); never imports JAX."""
    jax = JAX.loaded()
    if jax is None:
        return False
    tracer = getattr(getattr(jax, "core", None), "Tracer", None)
    return tracer is not None and isinstance(value, tracer)


def tracer_message(value: Any) -> str:
    """Why a tracer cannot be a launch argument, and what to do instead."""
    aval = getattr(value, "aval", None)
    return (
        f"got a JAX tracer ({aval or type(value).__name__}): inside jax.jit, grad or vmap "
        f"values have no data yet, and kdsl.launch runs at once on concrete values. "
        f"Launch outside the traced function, or mark the value static "
        f"(jax.jit(..., static_argnums=...))"
    )


def tracer_message_or_none(value: Any) -> str | None:
    """``tracer_message(value)`` for a JAX tracer, None for anything else."""
    return tracer_message(value) if is_tracer(value) else None


def device_from_jax(jax_device: Any) -> Device:
    """The kdsl device of a JAX device (``cpu`` or ``cuda:N``)."""
    platform = getattr(jax_device, "platform", None)
    if platform == "cpu":
        return get_device("cpu")
    if platform in ("gpu", "cuda"):
        index = getattr(jax_device, "local_hardware_id", None)
        return JAX.cuda_device(jax_device.id if index is None else index, jax_device)
    raise JAX.no_device(f"JAX device {jax_device!r}")


def device_to_jax(warp_device: Any) -> Any:
    """The JAX device of a kdsl device."""
    jax = _jax()
    dev = get_device(warp_device)
    try:
        devices = jax.devices("cpu" if dev.is_cpu else "cuda")
    except RuntimeError as e:
        raise InteropDeviceError(f"JAX has no device for '{dev}': {e}") from None
    if dev.is_cpu:
        return devices[0]
    for d in devices:
        if getattr(d, "local_hardware_id", d.id) == dev.ordinal:
            return d
    raise InteropDeviceError(f"JAX has no device for '{dev}' (it has {devices})")


def dtype_from_jax(jax_dtype: Any) -> type:
    """The kdsl scalar class of a JAX dtype; bfloat16 and complex raise ``TypeError``."""
    try:
        npd = np.dtype(jax_dtype)
    except TypeError:
        raise InteropTypeError(f"{jax_dtype!r} is not a JAX dtype") from None
    return public_scalar(scalar_from_numpy_dtype(npd, f"JAX dtype {npd.name}"))


def dtype_to_jax(warp_dtype: Any) -> Any:
    """The JAX scalar type (``jax.numpy.float32``...) of a kdsl scalar type."""
    return JAX.dtype_to(warp_dtype, _jax().numpy)


def from_jax(jax_array: Any, dtype: Any = None) -> array:
    """A kdsl array sharing a JAX array's buffer (no copy), through DLPack."""
    if is_tracer(jax_array):
        raise KdslError("from_jax(): " + tracer_message(jax_array))
    jax = _jax()
    if not isinstance(jax_array, jax.Array):
        raise KdslError(f"from_jax() takes a jax.Array, not {type(jax_array).__name__}")
    dtype_from_jax(jax_array.dtype)  # bfloat16/complex: a clear error before DLPack
    return from_dlpack(jax_array, dtype)


def to_jax(warp_array: array) -> Any:
    """A JAX array over kdsl array ``warp_array``'s memory, through DLPack.

    Element dims are appended (a ``vec3`` array gives an ``(n, 3)`` JAX array). On a
    GPU, JAX's stream waits for kdsl's. On the CPU, JAX copies instead of sharing
    when the buffer is not 64-byte aligned or is read-only (an array from ``from_jax``).
    """
    if not isinstance(warp_array, array):
        raise KdslError(f"to_jax() takes a kdsl array, not {type(warp_array).__name__}")
    if warp_array.__kdsl_type__.dtype is T.BF16:  # DLPack would hand JAX its uint16 bits
        raise InteropTypeError(BF16_HINT.format(what="to_jax() of a bfloat16 array"))
    buf = warp_array._buf
    if warp_array.device.is_cpu and not buf.flags.writeable:
        # JAX asks for a legacy capsule, which cannot carry NumPy's read-only flag
        # (an array from from_jax is read-only): hand JAX a copy, which it cannot tell apart.
        buf = np.array(buf)
    return _jax().dlpack.from_dlpack(Exporter(buf, warp_array.device))
