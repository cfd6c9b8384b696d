"""The compression of grids in NanoVDB files (``io::Codec``).

With ``NONE`` a grid is stored as its raw bytes. With ``ZIP`` (zlib) and ``BLOSC`` it is
stored as chunks, each an int64 byte count followed by that many compressed bytes: one
chunk for ZIP, chunks of at most 1 GiB of grid for BLOSC (NanoVDB's ``io/IO.h``). ZIP uses
the standard library's zlib; BLOSC needs the optional ``blosc`` package (the ``volume``
extra: ``pip install kdsl[volume]``).

Decompression never trusts a size it reads: output is bounded by the grid size the
metadata announced, and a chunk's size by the bytes left in the buffer.
"""

from __future__ import annotations

import struct
import zlib
from types import ModuleType

from kdsl.geometry.nanovdb.errors import NanoVDBCodecError, NanoVDBError
from kdsl.geometry.nanovdb.layout import Codec

#: NanoVDB compresses at most this many grid bytes per BLOSC chunk.
BLOSC_MAX_CHUNK = 1 << 30
_BLOSC_HEADER = 16  # blosc's chunk header: its bytes 4..8 are the uncompressed size
_CHUNK_SIZE = struct.Struct("<q")


def parse_codec(codec: str | int | Codec) -> Codec:
    """A codec from its name ("none", "zip", "blosc", any case) or number."""
    if isinstance(codec, str):
        try:
            return Codec[codec.upper()]
        except KeyError:
            pass
    elif isinstance(codec, int) and not isinstance(codec, bool):
        try:
            return Codec(codec)
        except ValueError:
            pass
    raise NanoVDBCodecError(f"unsupported NanoVDB codec {codec!r}: use 'none', 'zip' or 'blosc'")


def _blosc(source: str) -> ModuleType:
    try:
        import blosc  # an optional dependency: imported when a file needs it
    except ImportError:
        raise NanoVDBCodecError(
            f"{source}: BLOSC compression needs the 'blosc' package, which is not installed "
            "(pip install kdsl[volume])"
        ) from None
    return blosc


def compress_grid(data: bytes | memoryview, codec: Codec, source: str = "<bytes>") -> bytes:
    """The bytes of one grid as a file stores them under ``codec``."""
    if codec == Codec.NONE:
        return bytes(data)
    if codec == Codec.ZIP:
        chunks = [zlib.compress(data)]
    else:
        blosc = _blosc(source)
        view = memoryview(data)
        # typesize 4 and LZ4, as NanoVDB writes them (values are mostly 4-byte words)
        chunks = [
            blosc.compress(bytes(view[i : i + BLOSC_MAX_CHUNK]), typesize=4, cname="lz4")
            for i in range(0, max(len(view), 1), BLOSC_MAX_CHUNK)
        ]
    return b"".join(_CHUNK_SIZE.pack(len(c)) + c for c in chunks)


def _chunk(buf: memoryview, pos: int, source: str, what: str) -> tuple[memoryview, int]:
    if pos + 8 > len(buf):
        raise NanoVDBError(f"{source}: truncated: {what} ends before its chunk size")
    (size,) = _CHUNK_SIZE.unpack_from(buf, pos)
    if size <= 0 or size > len(buf) - pos - 8:
        raise NanoVDBError(
            f"{source}: corrupt: {what} has a compressed chunk of {size} bytes at byte {pos}, "
            f"but {len(buf) - pos - 8} bytes remain"
        )
    return buf[pos + 8 : pos + 8 + size], pos + 8 + size


def decompress_grid(
    buf: memoryview, pos: int, grid_size: int, codec: Codec, source: str, what: str
) -> tuple[bytes, int]:
    """Read the ``grid_size`` bytes of one grid stored at ``buf[pos:]`` under ``codec``;
    return them and the position after the stored grid."""
    if codec == Codec.NONE:
        if grid_size > len(buf) - pos:
            raise NanoVDBError(f"{source}: truncated: {what} needs {grid_size} bytes at byte "
                               f"{pos}, {len(buf) - pos} remain")  # fmt: skip
        return bytes(buf[pos : pos + grid_size]), pos + grid_size
    if codec == Codec.ZIP:
        chunk, pos = _chunk(buf, pos, source, what)
        inflater = zlib.decompressobj()
        try:
            out = inflater.decompress(chunk, grid_size)  # at most grid_size bytes
        except zlib.error as err:
            raise NanoVDBError(f"{source}: corrupt ZIP data in {what}: {err}") from None
        if len(out) != grid_size or inflater.unconsumed_tail or not inflater.eof:
            raise NanoVDBError(f"{source}: corrupt ZIP data in {what}: it does not inflate to "
                               f"the {grid_size} bytes its metadata gives")  # fmt: skip
        return out, pos
    blosc = _blosc(source)
    parts, left = [], grid_size
    while left > 0:
        chunk, pos = _chunk(buf, pos, source, what)
        want = min(left, BLOSC_MAX_CHUNK)
        if len(chunk) < _BLOSC_HEADER or int.from_bytes(chunk[4:8], "little") != want:
            raise NanoVDBError(f"{source}: corrupt BLOSC data in {what}: a chunk does not "
                               f"hold the {want} bytes expected")  # fmt: skip
        try:
            part = blosc.decompress(bytes(chunk))
        except Exception as err:  # blosc raises plain RuntimeError/ValueError
            raise NanoVDBError(f"{source}: corrupt BLOSC data in {what}: {err}") from None
        if len(part) != want:
            raise NanoVDBError(f"{source}: corrupt BLOSC data in {what}")
        parts.append(part)
        left -= want
    return b"".join(parts), pos
