"""NanoVDB grid checksums: two CRC-32s packed in ``GridData.mChecksum``.

The low word covers the head, the high word the tail (NanoVDB's ``tools/GridChecksum.h``):

- grids of version 32.7 and later: the head is bytes ``[16, 736)`` (the grid and tree
  headers after the magic and the checksum itself); the tail is a CRC-32 of the CRC-32s
  of the 4 KiB blocks of bytes ``[736, grid_size)``, the last block taking the remainder
  (a tail shorter than one block has no blocks, and a CRC of no bytes is 0);
- grids of 32.6 and earlier: the head runs from byte 16 to the first upper node; the tail
  is a CRC-32 of each node's CRC-32 (upper, lower, then leaf nodes, in order).

A word of all ones means "not computed"; a checksum of all ones is "disabled" and always
passes. CRC-32 is zlib's (polynomial 0xEDB88320).
"""

from __future__ import annotations

import zlib

import numpy as np

from kdsl.geometry.nanovdb.layout import (
    CHECKSUM_DISABLED,
    CHECKSUM_HALF_DISABLED,
    GRID_SIZE,
    TREE_SIZE,
    make_version,
)

_BLOCK = 1 << 12
_HEAD_START = 16
_NEW_CHECKSUM_SINCE = make_version(32, 6, 0)  # versions above this use blocked CRCs


def _block_crc(data: memoryview) -> int:
    blocks = len(data) >> 12
    crcs = np.empty(blocks, dtype="<u4")
    for b in range(blocks):
        end = len(data) if b + 1 == blocks else (b + 1) * _BLOCK
        crcs[b] = zlib.crc32(data[b * _BLOCK : end])
    return zlib.crc32(crcs.tobytes())


def grid_checksum(
    data: bytes | memoryview, version: int, node_spans: tuple[tuple[int, int, int], ...] = ()
) -> int:
    """The full 64-bit checksum of the grid ``data`` written with packed ``version``.

    ``node_spans`` matters only for grids of version 32.6.0 and earlier: the (offset,
    count, size) of the upper, lower and leaf node arrays, in that order."""
    view = memoryview(data)
    if version > _NEW_CHECKSUM_SINCE:
        head = zlib.crc32(view[_HEAD_START : GRID_SIZE + TREE_SIZE])
        tail = _block_crc(view[GRID_SIZE + TREE_SIZE :])
    else:
        first_node = next((off for off, count, _ in node_spans if count), len(view))
        head = zlib.crc32(view[_HEAD_START:first_node])
        crcs = [
            zlib.crc32(view[off + i * size : off + (i + 1) * size])
            for off, count, size in node_spans
            for i in range(count)
        ]
        tail = zlib.crc32(np.asarray(crcs, dtype="<u4").tobytes())
    return head | (tail << 32)


def checksum_matches(stored: int, computed: int) -> bool:
    """Whether a ``stored`` checksum agrees with the ``computed`` one: a disabled
    checksum always does; a half one (tail all ones) compares the head only."""
    if stored == CHECKSUM_DISABLED:
        return True
    if stored >> 32 == CHECKSUM_HALF_DISABLED:
        return (stored & 0xFFFFFFFF) == (computed & 0xFFFFFFFF)
    return stored == computed
