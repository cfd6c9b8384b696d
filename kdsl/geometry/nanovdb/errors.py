"""The errors of the NanoVDB reader, writer and builder."""

from __future__ import annotations

from kdsl.errors import KdslError


class NanoVDBError(KdslError, RuntimeError):
    """A NanoVDB file or buffer kdsl cannot read: truncated, corrupt, of another major
    version, of an unsupported grid type, or with a wrong checksum. The message names
    the source (file name or ``<bytes>``) and what is wrong. A ``RuntimeError`` too, as
    Warp raises for these."""


class NanoVDBCodecError(NanoVDBError):
    """A compression codec kdsl cannot use: unknown, or Blosc without the ``blosc``
    package (``pip install kdsl[volume]``)."""
