"""Builds of collected geometry objects, kept for the next object of the same shape.

A fresh ``Bvh`` or ``Mesh`` spends most of its host time making what a rebuild reuses:
its buffers, their views and its prepared launches (whose first run packs their
arguments: about half of a fresh lbvh build's host time). When the owner of a build is
collected, the build goes into a ``RecycleBin``, filed under the arrays it reads (by
identity: its prepared launches hold their memory) and its sizes; the next object
made over the same arrays with the same sizes takes it instead of making its own, so
its first build costs what a rebuild does. Every build is written whole by its next
run, so a taken build gives exactly what a new one would.

A bin holds its few most recent builds (the oldest goes when a new one comes, and its
memory back to the pool with it); a build holds the arrays it was filed under, so
those stay alive while it waits. ``clear()`` empties every bin.
"""

from __future__ import annotations

import threading
import weakref
from collections.abc import Callable
from typing import Any

_bins: weakref.WeakSet[RecycleBin] = weakref.WeakSet()


class RecycleBin:
    """At most ``capacity`` builds of collected owners, each filed under ``(inputs,
    shape)``: ``inputs`` a tuple of objects matched by identity, ``shape`` a tuple of
    values matched by equality."""

    def __init__(self, capacity: int) -> None:
        self.capacity = capacity
        # Oldest first, by a running number. The lock is reentrant and ``take`` works on
        # a snapshot: a collection during ``take`` may run ``_put`` on the same thread.
        self._kept: dict[int, tuple[tuple, tuple, Any]] = {}
        self._count = 0
        self._lock = threading.RLock()
        _bins.add(self)

    def take(self, inputs: tuple, shape: tuple) -> Any | None:
        """The newest build filed under ``inputs`` and ``shape`` (removed), or None."""
        with self._lock:
            for k, (kept_inputs, kept_shape, _) in reversed(list(self._kept.items())):
                if (
                    kept_shape == shape
                    and len(kept_inputs) == len(inputs)
                    and all(a is b for a, b in zip(kept_inputs, inputs))
                ):
                    entry = self._kept.pop(k, None)
                    if entry is not None:
                        return entry[2]
        return None

    def keep_when_collected(self, owner: Any, inputs: tuple, shape: tuple, build: Any,
                            usable: Callable[[Any], bool]) -> None:  # fmt: skip
        """File ``build`` under ``inputs`` and ``shape`` when ``owner`` is collected, if
        ``usable(build)`` says so then (a build cut short by an error is not). Neither
        ``build`` nor ``inputs`` may refer to ``owner``."""
        finalizer = weakref.finalize(owner, self._put, inputs, shape, build, usable)
        finalizer.atexit = False

    def _put(self, inputs: tuple, shape: tuple, build: Any, usable: Callable[[Any], bool]) -> None:
        if self.capacity <= 0 or not usable(build):
            return
        with self._lock:
            self._count += 1
            self._kept[self._count] = (inputs, shape, build)
            while len(self._kept) > self.capacity:
                del self._kept[next(iter(self._kept))]

    def __len__(self) -> int:
        return len(self._kept)

    def clear(self) -> None:
        """Drop every kept build."""
        with self._lock:
            self._kept.clear()


def clear() -> None:
    """Empty every bin (their builds' memory goes back to the pool)."""
    for b in list(_bins):
        b.clear()
