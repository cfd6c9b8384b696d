"""Writing new by-value launch arguments into a packed parameter buffer, in place.

A patchable launch (``Backend.prepare_patchable``) packs its arguments once and, before
each run, rewrites only its scalar, vector, matrix and handle parameters. The backends'
packers know each parameter's offset and ``struct`` format; ``make_writer`` groups
consecutive parameters into one ``pack_into`` each (rewriting only the padding between
them, never another parameter's bytes).
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence
from typing import Any

from kdsl.errors import KdslLaunchError

#: Appends one value's ``struct`` fields to a list.
Flatten = Callable[[Any, list], None]


def make_writer(
    indices: Sequence[int],
    offsets: Sequence[int],
    fields: Sequence[tuple[str, int]],
    flatten: Sequence[Flatten | None],
) -> Callable[[Any, Sequence[Any]], None]:
    """``write(buf, values)`` writing ``values`` (one per parameter of ``indices``,
    ascending) into ``buf`` at the parameters' ``offsets``.

    ``fields[i]`` is parameter ``i``'s ``struct`` format (from its offset, no byte-order
    prefix) and size; ``flatten[i]`` None packs its value as one field, else appends its
    fields to a list. A value ``struct`` cannot pack raises ``KdslLaunchError``.
    """
    runs: list[tuple[int, struct.Struct, list, bool, int, int]] = []
    k = 0
    while k < len(indices):
        lo = k
        fmt, end = "<", offsets[indices[k]]
        while k < len(indices) and (k == lo or indices[k] == indices[k - 1] + 1):
            i = indices[k]
            pad = offsets[i] - end
            fmt += (f"{pad}x" if pad else "") + fields[i][0]
            end = offsets[i] + fields[i][1]
            k += 1
        flat = [flatten[i] for i in indices[lo:k]]
        plain = all(f is None for f in flat)
        runs.append((offsets[indices[lo]], struct.Struct(fmt), flat, plain, lo, k))

    def write(buf: Any, values: Sequence[Any]) -> None:
        try:
            for offset, st, flat, plain, lo, hi in runs:
                if plain:
                    st.pack_into(buf, offset, *values[lo:hi])
                    continue
                vals: list = []
                for f, v in zip(flat, values[lo:hi]):
                    if f is None:
                        vals.append(v)
                    else:
                        f(v, vals)
                st.pack_into(buf, offset, *vals)
        except struct.error as e:
            raise KdslLaunchError(f"cannot pass the launch arguments to the kernel: {e}") from None

    return write


#: A writer: ``write(buf, values)`` (see ``make_writer``).
Writer = Callable[[Any, Sequence[Any]], None]


class Writers:
    """A packer's writers, one per set of by-value parameter indices, each made once by
    ``make(indices)`` (every patchable launch of a kernel asks for one)."""

    __slots__ = ("_made", "_make")

    def __init__(self, make: Callable[[tuple[int, ...]], Writer]) -> None:
        self._make = make
        self._made: dict[tuple[int, ...], Writer] = {}

    def get(self, indices: Sequence[int]) -> Writer:
        """The writer of ``indices`` (made now if it is the first time)."""
        key = tuple(indices)
        made = self._made.get(key)
        if made is None:
            made = self._made[key] = self._make(key)
        return made
