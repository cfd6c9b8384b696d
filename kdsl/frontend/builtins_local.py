"""Thread-local arrays in kernels: ``zeros(shape, dtype)`` (Warp's ``fixedarray``) and
kdsl's ``ext.empty(shape, dtype)``.

In Python scope ``kdsl.zeros`` allocates a runtime array; inside a kernel or a
``@kdsl.func`` the same name makes a zero-filled array private to the running thread
(``kd.local_array``), as in Warp 1.19. The runtime sits above the frontend, so it hands
its ``zeros`` down once (``kdsl.runtime.api`` calls ``register_host_alias``, see
``kdsl.frontend.builtins``); ``LOCAL_ZEROS`` is the builtin it is mapped onto.

``LOCAL_EMPTY`` (``kdsl.ext.empty``, a kdsl extension: Warp has no kernel-scope
spelling for it) makes the same array without the fill (``kd.local_array`` with
``fill = "none"``): its contents are undefined until written, for scratch that is
always written before it is read, such as a traversal stack.

The shape must be a compile-time constant: an integer or a tuple of 1 to 4 integers
(literals, ``kdsl.constant`` values, ``static(...)`` results or closure constants).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from kdsl.errors import KdslTypeError
from kdsl.frontend.builtins_base import Builtin
from kdsl.frontend.values import describe, is_weak
from kdsl.ir.ops_local import MAX_LOCAL_BYTES, local_array_error
from kdsl.ir.types import F32, ArrayType, Type
from kdsl.types import type_of


def _static_shape(em, name: str, shape: Any, node) -> tuple[int, ...]:
    dims = shape if isinstance(shape, tuple | list) else (shape,)
    for d in dims:
        if not (is_weak(d) and isinstance(d, int) and not isinstance(d, bool)):
            raise em.error(
                KdslTypeError,
                f"{name}() in a kernel makes a fixed-size local array: its shape must be a "
                f"compile-time constant (an int or a tuple of ints), not {describe(d)}; "
                "use wp.constant(...) or wp.static(...) for a computed size",
                node,
            )
    return tuple(int(d) for d in dims)


def _dtype(em, name: str, dtype: Any, node) -> Type:
    try:
        return type_of(dtype)
    except (TypeError, KeyError):
        raise em.error(KdslTypeError, f"{name}(): dtype must be a kdsl type, not "
                       f"{describe(dtype)}", node) from None  # fmt: skip


def _local(name: str, fill: str) -> Callable[..., Any]:
    """The lowering of the builtin ``name``: a ``kd.local_array`` with ``fill``."""

    def lower(em, args: list[Any], node, **kw: Any) -> Any:
        given = dict(zip(("shape", "dtype"), args))
        if set(given) & set(kw):
            raise em.error(KdslTypeError, f"{name}() got an argument twice", node)
        given.update(kw)
        if "shape" not in given:
            raise em.error(KdslTypeError, f"{name}() needs a shape", node)
        shape = _static_shape(em, name, given["shape"], node)
        t = _dtype(em, name, given["dtype"], node) if "dtype" in given else F32
        why = local_array_error(t, shape)
        if why is not None:
            raise em.error(KdslTypeError, f"{name}(): {why}", node)
        attrs: dict[str, Any] = {"shape": list(shape)}
        if fill != "zero":  # the default: zeros print as before
            attrs["fill"] = fill
        return em.emit_typed("kd.local_array", [], ArrayType(t, len(shape)), node, **attrs)

    return lower


LOCAL_ZEROS = Builtin(
    "zeros",
    _local("zeros", "zero"),
    "``zeros(shape, dtype=float)``: in a kernel, a zero-filled array private to the thread "
    "(Warp's ``fixedarray``), with a compile-time constant ``shape`` (an int or a tuple of "
    f"1 to 4 ints) and at most {MAX_LOCAL_BYTES} bytes. It is an ordinary array: index it, "
    "take views, use atomics, pass it to a ``@kdsl.func``. In Python scope ``kdsl.zeros`` "
    "allocates a device array.",
    (0, 2),
    "memory",
    keywords=("shape", "dtype"),
)

LOCAL_EMPTY = Builtin(
    "ext.empty",
    _local("ext.empty", "none"),
    "``ext.empty(shape, dtype=float)``: in a kernel, an array private to the thread whose "
    "contents are undefined until written (kdsl's extension: ``zeros`` without the fill, "
    "which Warp cannot spell). Shape, dtype and size rules are ``zeros``'s. Write an "
    "element before reading it; ``interp`` fills the array with a poison pattern (NaN "
    "floats, 0xA5 bytes) so that a read before a write shows. For scratch written before "
    "it is read, such as a traversal stack: no stores at creation.",
    (0, 2),
    "memory",
    keywords=("shape", "dtype"),
)
