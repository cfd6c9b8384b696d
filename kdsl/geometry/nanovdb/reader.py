"""``read_grids``: the grids of a NanoVDB file or buffer, validated.

Two inputs are accepted, as NanoVDB's own ``io::readGrids`` accepts them: a file of
segments (``FileHeader``, per-grid ``FileMetaData`` and names, then the grids, raw or
compressed; see ``layout``) and a raw grid buffer (grids back to back, as
``warp.Volume.array()`` and ``kdsl.Volume.array()`` give them).

Nothing read is trusted: every size, count and offset is checked against the bytes that
hold it before anything is allocated or read through it (``grid_validation``), so a
truncated or corrupt input raises ``NanoVDBError`` naming the source and the fault,
never an ``IndexError``, a crash or a huge allocation.
"""

from __future__ import annotations

import os
import struct
from typing import Any

from kdsl.geometry.nanovdb.codecs import decompress_grid
from kdsl.geometry.nanovdb.errors import NanoVDBCodecError, NanoVDBError
from kdsl.geometry.nanovdb.grid_info import GridInfo
from kdsl.geometry.nanovdb.grid_validation import parse_grid
from kdsl.geometry.nanovdb.layout import (
    FILE_HEADER_SIZE,
    FILE_MAGICS,
    FILE_META_OFF_GRID_SIZE,
    FILE_META_OFF_NAME_SIZE,
    FILE_METADATA_SIZE,
    GRID_MAGICS,
    GRID_OFF_DATA2,
    GRID_OFF_GRID_SIZE,
    GRID_OFF_VERSION,
    GRID_SIZE,
    MAGIC_GRID,
    MAJOR_VERSION,
    TREE_SIZE,
    Codec,
    version_major,
    version_string,
)

#: Grid names longer than this (with the NUL) are refused: NanoVDB's own limit on a
#: grid's long name is far below it, and it bounds what a corrupt size can allocate.
MAX_NAME_SIZE = 1 << 20
#: The largest grid size accepted from a file's metadata (256 TiB), bounding what a
#: corrupt size can ask a decompressor for.
MAX_GRID_SIZE = 1 << 48


def _source_bytes(file_or_bytes: Any) -> tuple[memoryview, str]:
    """The bytes to read and a name for messages."""
    if isinstance(file_or_bytes, str | os.PathLike):
        path = os.fspath(file_or_bytes)
        try:
            with open(path, "rb") as f:
                return memoryview(f.read()), str(path)
        except OSError as err:
            raise NanoVDBError(f"{path}: cannot read NanoVDB file: {err.strerror}") from None
    if hasattr(file_or_bytes, "read"):
        data = file_or_bytes.read()
        name = getattr(file_or_bytes, "name", "<file>")
        if not isinstance(data, bytes | bytearray):
            raise NanoVDBError(f"{name}: a NanoVDB file must be opened in binary mode ('rb')")
        return memoryview(data), str(name)
    try:
        view = memoryview(file_or_bytes)
    except TypeError:
        raise NanoVDBError(
            f"load_from_nvdb needs a path, a binary file or a bytes-like buffer, "
            f"not {type(file_or_bytes).__name__}"
        ) from None
    return view.cast("B") if view.contiguous else memoryview(view.tobytes()), "<bytes>"


def _is_raw_grid(buf: memoryview) -> bool:
    """Whether ``buf`` starts with a grid rather than a file header (both may start with
    "NanoVDB0"); NanoVDB's ``GridData::isValid`` test."""
    if len(buf) < GRID_SIZE + TREE_SIZE:
        return False
    (magic,) = struct.unpack_from("<Q", buf, 0)
    if magic == MAGIC_GRID:
        return True
    if magic not in GRID_MAGICS:
        return False
    if struct.unpack_from("<Q", buf, GRID_OFF_DATA2)[0] == MAGIC_GRID:
        return True
    version, _flags, index, count = struct.unpack_from("<IIII", buf, GRID_OFF_VERSION)
    return version_major(version) == MAJOR_VERSION and 0 <= index < count


def _read_raw(buf: memoryview, source: str, verify: bool) -> list[GridInfo]:
    grids, pos = [], 0
    while pos < len(buf):
        if len(buf) - pos < GRID_SIZE + TREE_SIZE:
            raise NanoVDBError(f"{source}: truncated: {len(buf) - pos} bytes at byte {pos} "
                               f"cannot hold a grid")  # fmt: skip
        (size,) = struct.unpack_from("<Q", buf, pos + GRID_OFF_GRID_SIZE)
        if size < GRID_SIZE + TREE_SIZE or size > len(buf) - pos:
            raise NanoVDBError(f"{source}: grid {len(grids)} gives a size of {size} bytes, but "
                               f"{len(buf) - pos} bytes remain: truncated or corrupt")  # fmt: skip
        grids.append(parse_grid(bytes(buf[pos : pos + size]), source, len(grids), verify))
        pos += size
    return grids


def _read_header(buf: memoryview, pos: int, source: str) -> tuple[int, Codec]:
    if len(buf) - pos < FILE_HEADER_SIZE:
        raise NanoVDBError(f"{source}: truncated: a file header at byte {pos} needs 16 bytes")
    magic, version, count, codec = struct.unpack_from("<QIHH", buf, pos)
    if magic not in FILE_MAGICS:
        what = "a raw grid" if magic == MAGIC_GRID else f"0x{magic:016x}"
        raise NanoVDBError(f"{source}: not a NanoVDB file: wrong magic number at byte {pos} "
                           f"({what}; expected 'NanoVDB0' or 'NanoVDB2')")  # fmt: skip
    if version_major(version) != MAJOR_VERSION:
        raise NanoVDBError(f"{source}: unsupported NanoVDB version {version_string(version)}: "
                           f"kdsl reads major version {MAJOR_VERSION}")  # fmt: skip
    try:
        codec = Codec(codec)
    except ValueError:
        raise NanoVDBCodecError(f"{source}: unsupported codec {codec} in the file header at "
                                f"byte {pos} (known: 0 none, 1 zip, 2 blosc)") from None  # fmt: skip
    if count == 0:
        raise NanoVDBError(f"{source}: corrupt: a file segment at byte {pos} holds no grid")
    return count, codec


def _read_segments(buf: memoryview, source: str, verify: bool) -> list[GridInfo]:
    grids: list[GridInfo] = []
    pos = 0
    while pos < len(buf):
        count, codec = _read_header(buf, pos, source)
        pos += FILE_HEADER_SIZE
        metas = []
        for _ in range(count):
            if len(buf) - pos < FILE_METADATA_SIZE:
                raise NanoVDBError(f"{source}: truncated: grid metadata at byte {pos}")
            (size,) = struct.unpack_from("<Q", buf, pos + FILE_META_OFF_GRID_SIZE)
            (name_size,) = struct.unpack_from("<I", buf, pos + FILE_META_OFF_NAME_SIZE)
            pos += FILE_METADATA_SIZE
            if name_size > min(MAX_NAME_SIZE, len(buf) - pos):
                raise NanoVDBError(f"{source}: corrupt: a grid name of {name_size} bytes at "
                                   f"byte {pos}, {len(buf) - pos} remain")  # fmt: skip
            if not GRID_SIZE + TREE_SIZE <= size <= MAX_GRID_SIZE:
                raise NanoVDBError(f"{source}: corrupt: grid {len(grids) + len(metas)} has a "
                                   f"size of {size} bytes in its metadata")  # fmt: skip
            name = bytes(buf[pos : pos + name_size]).split(b"\0")[0].decode("utf-8", "replace")
            metas.append((size, name))
            pos += name_size
        for size, name in metas:
            what = f"grid {len(grids)} ({name!r})" if name else f"grid {len(grids)}"
            data, pos = decompress_grid(buf, pos, size, codec, source, what)
            grids.append(parse_grid(data, source, len(grids), verify))
    return grids


def read_grids(file_or_bytes: Any, verify_checksum: bool = True) -> list[GridInfo]:
    """Every grid of a NanoVDB file or buffer: a path, a binary file object, or a
    bytes-like object holding a ``.nvdb`` file or a raw grid buffer. Raises
    ``NanoVDBError`` (``NanoVDBCodecError`` for codecs) naming the source and the fault."""
    buf, source = _source_bytes(file_or_bytes)
    if len(buf) == 0:
        raise NanoVDBError(f"{source}: empty: no NanoVDB grid")
    read = _read_raw if _is_raw_grid(buf) else _read_segments
    grids = read(buf, source, verify_checksum)
    if not grids:
        raise NanoVDBError(f"{source}: no NanoVDB grid")
    return grids
