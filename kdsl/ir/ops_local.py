"""``kd.local_array``: an array private to one thread (Warp's ``fixedarray``).

Its value is an ordinary array descriptor (pointer, shape, strides) over memory that
belongs to the running thread, so every memory op (``kd.load``, ``kd.store``, the
atomics, ``kd.array_view``, ``kd.array_shape``) and every function taking an array
works on it unchanged. The shape is an attribute: it must be known when the kernel is
compiled, which lets the backends place the storage on the stack (cpu: an ``alloca``
in the function's entry block, which LLVM promotes to registers when every index is
constant; cuda: a C local array).

The ``fill`` attribute says what each run of the op leaves in the storage:

- ``"zero"`` (the default, also when the attribute is absent: Warp's ``zeros`` in a
  kernel): fresh zeros each time the op runs;
- ``"none"`` (kdsl's ``kdsl.ext.empty``): nothing; the contents are undefined until
  written, and reading an element first is a bug of the kernel, as reading an
  uninitialized C array. The backends emit no store: a traversal stack that is always
  written before it is read (pushed, then popped) costs no memory traffic at
  creation. ``interp``, the reference, fills such an array with ``poison_value``'s
  pattern (NaN for floating-point fields, ``0xA5`` bytes for integers and bools),
  deterministically, so a test that reads before writing sees garbage it can detect
  instead of zeros that happen to be right.

The op is not pure (two local arrays of one shape are two memories, never merged by
CSE) but has no effect other than producing new memory, so it carries ``READS``: DCE
removes one nobody uses, and the adjoint's forward replay repeats it.
"""

from __future__ import annotations

import math

import numpy as np

from kdsl.ir.catalog import CATALOG, READS
from kdsl.ir.types import ArrayType, HandleType, Type, storage_dtype

#: The largest local array, in bytes. A thread's stack (cpu) and its local memory
#: (cuda) are small and slow to spill into: larger scratch belongs in a global array.
MAX_LOCAL_BYTES = 64 * 1024
#: The values of the ``fill`` attribute (see the module docstring); absent means "zero".
FILLS = ("zero", "none")
#: The byte the poison pattern gives integer and bool fields (-1515870811 as an int32).
POISON_BYTE = 0xA5


def local_array_error(dtype: Type, shape: tuple[int, ...]) -> str | None:
    """Why a local array of ``dtype`` and ``shape`` cannot exist, or None if it can."""
    if not 1 <= len(shape) <= 4:
        return f"a local array has 1 to 4 dimensions, not {len(shape)}"
    if any(not isinstance(n, int) or isinstance(n, bool) or n < 1 for n in shape):
        return f"a local array's shape holds positive integers, not {tuple(shape)}"
    if isinstance(dtype, ArrayType | HandleType):
        return f"a local array cannot hold values of type {dtype}"
    try:
        itemsize = storage_dtype(dtype).itemsize
    except TypeError:
        return f"a local array cannot hold values of type {dtype}"
    size = math.prod(shape) * itemsize
    if size > MAX_LOCAL_BYTES:
        return (
            f"a local array of shape {tuple(shape)} and type {dtype} takes {size} bytes, over "
            f"the limit of {MAX_LOCAL_BYTES} bytes per thread; use a global array instead"
        )
    return None


def _verify(op) -> None:
    (res,) = op.results
    if op.operands:
        raise TypeError("kd.local_array takes no operands")
    if not isinstance(res.type, ArrayType):
        raise TypeError(f"kd.local_array gives an array, not {res.type}")
    shape = op.attrs["shape"]
    if not isinstance(shape, list | tuple) or len(shape) != res.type.ndim:
        raise TypeError(f"kd.local_array shape {shape!r} does not match {res.type}")
    why = local_array_error(res.type.dtype, tuple(shape))
    if why is not None:
        raise TypeError(why)
    if fill_of(op) not in FILLS:
        raise TypeError(f"kd.local_array fill must be one of {FILLS}, not {fill_of(op)!r}")


def fill_of(op) -> str:
    """What a ``kd.local_array`` op leaves in its storage: ``"zero"`` or ``"none"``."""
    return op.attrs.get("fill", "zero")


def poison_value(dt: np.dtype, shape: tuple[int, ...]) -> np.ndarray:
    """An array of NumPy ``dt`` and ``shape`` holding the poison pattern: NaN in every
    floating-point field (structured dtypes field by field), ``POISON_BYTE`` bytes
    elsewhere."""
    out = np.zeros(shape, dtype=dt)  # (a vector dtype gives its components' axes too)
    out.reshape(-1).view(np.uint8)[...] = POISON_BYTE
    _poison_floats(out, dt)
    return out


def _poison_floats(a: np.ndarray, dt: np.dtype) -> None:
    """Write NaN into every floating-point field of ``a`` (of dtype ``dt``), in place."""
    if dt.fields is not None:
        for name in dt.names:
            _poison_floats(a[name], dt.fields[name][0])
    elif (dt.subdtype[0] if dt.subdtype is not None else dt).kind in "fc":
        a[...] = np.nan


def _interp(ctx, op):
    t: ArrayType = op.results[0].type
    shape = tuple(op.attrs["shape"])
    dt = storage_dtype(t.dtype)
    if fill_of(op) == "none":
        return poison_value(dt, shape)
    return np.zeros(shape, dtype=dt)


def dense_strides(t: ArrayType, shape: tuple[int, ...], unit: int) -> list[int]:
    """Row-major strides of a dense array of ``t`` with ``shape``, in units of ``unit`` bytes."""
    step = storage_dtype(t.dtype).itemsize // unit
    out = []
    for n in reversed(shape):
        out.append(step)
        step *= n
    return out[::-1]


def is_local_array(v) -> bool:
    """Whether the value ``v`` is a ``kd.local_array`` result."""
    op = getattr(v, "op", None)
    return op is not None and op.opdef is LOCAL_ARRAY


LOCAL_ARRAY = CATALOG.define(
    "kd.local_array",
    "An array of constant ``shape`` private to the running thread (Warp's "
    "``zeros(shape, dtype)`` in a kernel, a ``fixedarray``): an ordinary array value, so "
    "every memory op and every function taking an array accept it. Each run of the op "
    "gives fresh zeros, or with ``fill = \"none\"`` (``kdsl.ext.empty``) contents undefined "
    "until written (``interp`` fills them with a NaN/0xA5 poison pattern). At most "
    f"{MAX_LOCAL_BYTES} bytes.",
    traits=frozenset({READS}), verifier=_verify, interp=_interp, required_attrs=("shape",),
    example="%0 = kd.local_array {shape = [8]} : array<f32, 1>", group="memory",
)  # fmt: skip

__all__ = ["FILLS", "LOCAL_ARRAY", "MAX_LOCAL_BYTES", "POISON_BYTE", "dense_strides",
           "fill_of", "is_local_array", "local_array_error", "poison_value"]  # fmt: skip
