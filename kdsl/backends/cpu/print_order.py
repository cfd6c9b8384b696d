"""Program order between Python's ``print`` and a kernel's ``printf``.

C's ``stdout`` is buffered apart from Python's ``sys.stdout``; a kernel that prints
runs between a flush of Python's buffer and a flush of C's (see ``printing``).
"""

from __future__ import annotations

import ctypes
import sys
from collections.abc import Callable
from functools import cache
from typing import Any


@cache
def _fflush() -> Any:
    return ctypes.CDLL(None).fflush


def flushing(fn: Callable[..., Any]) -> Callable[..., None]:
    """``fn`` (a native range function) run between flushes of Python's and C's stdout."""
    fflush = _fflush()

    def run(*args: Any) -> None:
        sys.stdout.flush()
        try:
            fn(*args)
        finally:
            fflush(None)

    return run
