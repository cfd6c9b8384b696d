"""Warp's ``config.verify_autograd_array_access``: warn when a recorded launch writes an
array that an earlier recorded launch read.

Reverse mode replays the recorded launches backwards, reading the arrays as they are
when ``backward()`` runs. A launch that overwrites an array an earlier launch read
(``x = f(x)`` in place, or a buffer reused between steps) makes the earlier launch's
adjoint see the new values, so its gradients are silently wrong. With the setting on,
each launch recorded on a tape marks the arrays it writes (warning, with the kernel,
parameter and definition site, when one was already marked read) and then the arrays
it reads, as Warp does; ``kdsl.copy`` and ``array.assign`` mark theirs too. A kernel
that writes after reading the same array within itself is not flagged (Warp flags
that when it compiles; kdsl's adjoint handles it per launch). Marks are per array and
shared by its views (a mark on a view also marks the array it views);
``tape.backward()`` and ``tape.reset()`` clear those of the arrays the tape recorded.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

from kdsl.ir.array_access import ParamAccess, array_param_access
from kdsl.runtime.array import array
from kdsl.runtime.logger import log_warning

#: kernel key -> its parameters' access, computed once per kernel instance.
_ACCESS: dict[str, list[ParamAccess]] = {}


def kernel_array_access(kernel: Any) -> list[ParamAccess]:
    """How ``kernel`` (a concrete instance) reads and writes each of its parameters."""
    found = _ACCESS.get(kernel.key)
    if found is None:
        found = _ACCESS[kernel.key] = array_param_access(kernel.build_module(), kernel.key)
    return found


def check_launch(kernel: Any, args: Sequence[Any]) -> None:
    """Mark the arrays a recorded launch of ``kernel`` writes (warning on those already
    read), then those it reads."""
    access = kernel_array_access(kernel)
    code = kernel.fn.__code__
    for name, a, acc in zip(kernel.arg_names, args, access):
        if isinstance(a, array) and acc.write:
            a.mark_write(
                arg_name=name, kernel_name=kernel.name, filename=code.co_filename,
                lineno=code.co_firstlineno,
            )  # fmt: skip
        if isinstance(a, array) and acc.read:
            a.mark_read()


def clear_read_marks(arrays: Iterable[Any]) -> None:
    """Clear the read marks of ``arrays`` (and of the arrays they view)."""
    for a in arrays:
        while isinstance(a, array):
            a.mark_init()
            a = a._viewed


def warn_write_after_read(a: array, site: dict[str, Any]) -> None:
    """Log Warp's warning for a write to ``a`` after a recorded launch read it."""
    where = f" at {site['filename']}:{site['lineno']}" if "filename" in site else ""
    if "kernel_name" in site and "arg_name" in site:
        writer = f" passed to argument {site['arg_name']} in kernel {site['kernel_name']}{where}"
        writer += " is being written to"
    elif "operation" in site:
        writer = f" is being written to by {site['operation']}{where}"
    else:
        writer = " is being written to"
    log_warning(
        f"Array {a.__kdsl_type__} of shape {a.shape}{writer} but has already been read from "
        "in a previous launch. This may corrupt gradient computation in the backward pass."
    )
