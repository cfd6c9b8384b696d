"""How the runtime reaches foreign-array code (DLPack, PyTorch, JAX) without importing it.

The runtime sits below ``kdsl.interop``: it never imports torch, JAX or the DLPack
helpers. Where a launch or an array needs them, it asks this registry, which
``kdsl.interop.api`` fills once, explicitly, when ``kdsl`` is imported:

- ``foreign_buffer(t, value, device)``: a DLPack or ``__array_interface__`` producer
  (a PyTorch tensor, a JAX array, ...) as a zero-copy buffer for a parameter of
  array type ``t``, or ``ArgError``;
- ``cached_buffer(t, value, device)``: the same for a value the interop layer has
  seen before (a PyTorch tensor handed to launches again and again), from its
  cache, or None; asked before the general checks, which it skips;
- ``tracer_message(value)``: a message when ``value`` is a JAX tracer (a launch
  cannot take one), else None;
- ``dlpack_export(buf, device, **options)``: a DLPack capsule of a kdsl array's buffer.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from kdsl.errors import KdslError

#: The hooks the runtime may ask for, with what each does (see the module docstring).
HOOKS = {
    "foreign_buffer": "read a DLPack or __array_interface__ producer as a launch buffer",
    "cached_buffer": "read a tensor seen before as a launch buffer, or None",
    "tracer_message": "say why a JAX tracer cannot be a launch argument",
    "dlpack_export": "export a kdsl array through DLPack",
}

_registered: dict[str, Callable[..., Any]] = {}


def register_adapter(hook: str, fn: Callable[..., Any]) -> None:
    """Provide ``hook`` (one of ``HOOKS``); providing one twice is an error."""
    if hook not in HOOKS:
        raise KdslError(f"unknown runtime adapter hook {hook!r} (hooks: {sorted(HOOKS)})")
    old = _registered.get(hook)
    if old is not None and old is not fn:
        raise KdslError(f"the runtime adapter hook {hook!r} is provided twice")
    _registered[hook] = fn


def adapter(hook: str) -> Callable[..., Any] | None:
    """The function providing ``hook``, or None when no interop layer registered one."""
    return _registered.get(hook)
