"""``kdsl.Texture1D``, ``Texture2D``, ``Texture3D``: Warp 1.19's experimental textures.

A texture holds its texels (every mip level, level 0 first) in one flat device array of
the texel format's width (``uint8``, ``uint16`` or ``uint32`` words), and the modes it
was made with. A kernel parameter annotated ``kdsl.Texture2D`` receives it as a record
(the struct ``kdsl.stdlib.texture.Texture2D``: the array and the modes), and
``texture_sample`` samples it with kdsl code, in software, on every backend: the same
result on interp, cpu and cuda (Warp's CUDA path uses hardware texture units instead;
docs/language.md lists the differences).
"""

from __future__ import annotations

import enum
from typing import Any, ClassVar

import numpy as np

from kdsl.runtime.array import array
from kdsl.runtime.device import Device, get_device
from kdsl.stdlib import texture as S
from kdsl.texture.formats import (
    FORMATS,
    INTEGER32,
    MAX_ELEMENTS,
    TextureError,
    mip_chain,
    mip_shapes,
    parse_data,
    texel_format,
)
from kdsl.types import dtype_from_numpy


class TextureFilterMode(enum.IntEnum):
    """Filter modes for texture sampling (Warp's values)."""

    CLOSEST = S.CLOSEST
    """Nearest-neighbor (point) filtering."""
    LINEAR = S.LINEAR
    """Linear, bilinear or trilinear filtering."""


class TextureAddressMode(enum.IntEnum):
    """What coordinates outside the texture read (Warp's values)."""

    WRAP = S.WRAP
    """Tile the texture."""
    CLAMP = S.CLAMP
    """Repeat the edge texels."""
    MIRROR = S.MIRROR
    """Tile the texture, every other copy mirrored."""
    BORDER = S.BORDER
    """Read zero outside the texture."""


class TextureResourceFlags(enum.IntEnum):
    """Warp's flags for registering OpenGL textures (``GLTextureResource``); kdsl has no
    OpenGL texture interop and keeps the enum for programs that name it."""

    NONE = 0x00
    READ_ONLY = 0x01
    WRITE_DISCARD = 0x02
    SURFACE_LDST = 0x04
    TEXTURE_GATHER = 0x08


_STORAGE = {1: np.uint8, 2: np.uint16, 4: np.uint32}


def _enum(kind: type[enum.IntEnum], value: Any, what: str) -> Any:
    try:
        return kind(value)
    except (TypeError, ValueError):
        raise TextureError(f"invalid texture {what}: {value!r}") from None


def _address_modes(ndim: int, address_mode: Any, per_axis: tuple) -> list[TextureAddressMode]:
    modes = []
    for axis, mode in enumerate(per_axis[:ndim]):
        if mode is None:
            mode = address_mode
            if isinstance(address_mode, tuple | list):
                mode = address_mode[axis] if axis < len(address_mode) else S.CLAMP
        modes.append(_enum(TextureAddressMode, mode, f"address mode for axis {axis}"))
    return modes + [TextureAddressMode.CLAMP] * (3 - ndim)


class Texture:
    """A 1-, 2- or 3-d texture on one device, sampled in kernels with ``texture_sample``.

    Experimental, as in Warp. Make one with ``Texture1D``, ``Texture2D`` or ``Texture3D``
    (as in Warp, this base class is not made directly). Texel types: ``uint8``,
    ``uint16``, ``int8``, ``int16`` (read normalized to [0, 1] or [-1, 1]), ``float16``,
    ``float32``, and ``uint32``/``int32`` (read as numbers; ``CLOSEST`` filtering only).
    """

    __kdsl_type__: ClassVar[Any] = None
    #: The dimensions of the subclass's textures.
    _dims: ClassVar[int] = 0

    def __init__(
        self, data: Any = None, width: int = 0, height: int = 0, depth: int = 0,
        num_channels: int = 0, dtype: Any = None, filter_mode: Any = None,
        address_mode: Any = TextureAddressMode.CLAMP, address_mode_u: Any = None,
        address_mode_v: Any = None, address_mode_w: Any = None, normalized_coords: bool = True,
        num_mip_levels: int = 1, mip_filter_mode: Any = None, device: Any = None,
        surface_access: bool = False, cuda_array: int = 0,
    ) -> None:  # fmt: skip
        """Make a texture from ``data`` (a NumPy array or a kdsl array: ``(width[,
        channels])``, ``(height, width[, channels])`` or ``(depth, height, width[,
        channels])``, or the same without channels for vector dtypes), or an empty one of
        ``width``/``height``/``depth``, ``num_channels`` (1, 2 or 4) and ``dtype``.
        ``num_mip_levels`` (0: the full chain) makes coarser levels from ``data`` with a
        2x box filter. ``surface_access`` and ``cuda_array`` (CUDA array interop) are not
        supported. (Here: ``Texture3D``'s signature; ``Texture1D`` and ``Texture2D`` take
        the arguments of their axes only.)"""
        ndim = self._dims
        if not ndim:
            raise TextureError("make a texture with kdsl.Texture1D, Texture2D or Texture3D")
        if cuda_array or surface_access:
            raise TextureError("kdsl textures live in plain device memory: cuda_array and "
                               "surface_access (CUDA array interop) are not supported")  # fmt: skip
        self._ndim = ndim
        self.device: Device = get_device(device)
        size = [width, height if ndim > 1 else 1, depth if ndim > 2 else 1]
        if data is not None:
            texels, channels = parse_data(data, ndim)
            given = (size[0], size[1], size[2], num_channels)
            found = (texels.shape[2], texels.shape[1], texels.shape[0], channels)
            for what, want, got in zip(("width", "height", "depth", "num_channels"), given, found):
                if want and want != got:
                    raise TextureError(f"specified texture {what} ({want}) does not match "
                                       f"the data's ({got})")  # fmt: skip
            if dtype is not None and texel_format(dtype) != texels.dtype:
                raise TextureError(f"specified texture dtype {dtype!r} does not match the "
                                   f"data's ({texels.dtype})")  # fmt: skip
            size, num_channels = list(found[:3]), channels
        else:
            texels = None
        for what, n in zip(("width", "height", "depth")[:ndim], size):
            if not isinstance(n, int | np.integer) or n <= 0:
                raise TextureError(f"texture {what} must be a positive integer, got {n!r}")
        if num_channels not in (1, 2, 4):
            raise TextureError(f"texture num_channels must be 1, 2 or 4, got {num_channels!r}")
        np_dtype = texels.dtype if texels is not None else texel_format(dtype or np.float32)
        self._size = tuple(int(n) for n in size)
        self._num_channels = int(num_channels)
        self._np_dtype = np_dtype
        self._shapes = mip_shapes(self._size, ndim, num_mip_levels)  # type: ignore[arg-type]
        if self.is_mipmapped and texels is None:
            raise TextureError("mipmapped textures need data at construction")
        self._init_modes(ndim, filter_mode, mip_filter_mode, address_mode,
                         (address_mode_u, address_mode_v, address_mode_w))  # fmt: skip
        self._normalized_coords = bool(normalized_coords)
        if texels is None:
            texels = np.zeros((self._size[2], self._size[1], self._size[0], num_channels),
                              np_dtype)  # fmt: skip
        levels = mip_chain(texels, self._shapes) if self.is_mipmapped else [texels]
        flat = np.concatenate([level.ravel() for level in levels])
        if flat.size > MAX_ELEMENTS:
            raise TextureError(f"texture has {flat.size} texel values; kernels index at most "
                               f"{MAX_ELEMENTS}")  # fmt: skip
        self._buffer = array(flat.view(_STORAGE[np_dtype.itemsize]), device=self.device)

    def _init_modes(self, ndim, filter_mode, mip_filter_mode, address_mode, per_axis) -> None:
        """The filter and address modes, with Warp's defaults and checks."""
        integer32 = FORMATS[self._np_dtype] in INTEGER32
        default = TextureFilterMode.CLOSEST if integer32 else TextureFilterMode.LINEAR
        self._filter_mode = _enum(TextureFilterMode, default if filter_mode is None
                                  else filter_mode, "filter mode")  # fmt: skip
        self._mip_filter_mode = _enum(TextureFilterMode, default if mip_filter_mode is None
                                      else mip_filter_mode, "mip filter mode")  # fmt: skip
        if integer32 and self._filter_mode != TextureFilterMode.CLOSEST:
            raise TextureError("32-bit integer textures require "
                               "filter_mode=TextureFilterMode.CLOSEST")  # fmt: skip
        if integer32 and self.is_mipmapped and self._mip_filter_mode != TextureFilterMode.CLOSEST:
            raise TextureError("32-bit integer mipmapped textures require "
                               "mip_filter_mode=TextureFilterMode.CLOSEST")  # fmt: skip
        self._address = _address_modes(ndim, address_mode, per_axis)

    # -- the record kernels read (kdsl.stdlib.texture) --------------------------------

    def _view(self, itemsize: int) -> array | None:
        return self._buffer if self._np_dtype.itemsize == itemsize else None

    texels8 = property(
        lambda self: self._view(1), doc="The texel buffer of an 8-bit format (else None)."
    )
    texels16 = property(
        lambda self: self._view(2), doc="The texel buffer of a 16-bit format (else None)."
    )
    texels32 = property(
        lambda self: self._view(4), doc="The texel buffer of a 32-bit format (else None)."
    )
    texel_format = property(
        lambda self: FORMATS[self._np_dtype], doc="Warp's code of the texel format."
    )

    @property
    def texel_sign(self) -> int:
        """The sign bit of 8- and 16-bit signed texels (else 0)."""
        signed = self._np_dtype.kind == "i" and self._np_dtype.itemsize < 4
        return 1 << (8 * self._np_dtype.itemsize - 1) if signed else 0

    @property
    def texel_scale(self) -> float:
        """What 8- and 16-bit integer texels are divided by (their largest value)."""
        small = self._np_dtype.kind in "iu" and self._np_dtype.itemsize < 4
        return float(np.iinfo(self._np_dtype).max) if small else 1.0

    normalized = property(
        lambda self: int(self._normalized_coords), doc="1 with normalized coordinates, else 0."
    )

    # -- Warp's properties ----------------------------------------------------------------

    ndim = property(lambda self: self._ndim, doc="Dimensions: 1, 2 or 3.")
    width = property(lambda self: self._size[0], doc="Texels along u (level 0).")
    height = property(
        lambda self: self._size[1], doc="Texels along v (level 0; 1 for a 1-d texture)."
    )
    depth = property(lambda self: self._size[2], doc="Texels along w (level 0; 1 below 3-d).")
    num_channels = property(lambda self: self._num_channels, doc="Channels per texel: 1, 2 or 4.")
    dtype = property(
        lambda self: dtype_from_numpy(self._np_dtype), doc="The texel type (``kdsl.uint8``...)."
    )
    filter_mode = property(lambda self: self._filter_mode, doc="Filtering within a mip level.")
    mip_filter_mode = property(
        lambda self: self._mip_filter_mode, doc="Filtering between mip levels."
    )
    num_mip_levels = property(lambda self: len(self._shapes), doc="Mip levels (1: not mipmapped).")
    is_mipmapped = property(
        lambda self: len(self._shapes) > 1, doc="Whether the texture has more than one mip level."
    )
    address_mode_u = property(lambda self: self._address[0], doc="Address mode along u.")
    address_mode_v = property(
        lambda self: self._address[1], doc="Address mode along v (``CLAMP`` below 2-d)."
    )
    address_mode_w = property(
        lambda self: self._address[2], doc="Address mode along w (``CLAMP`` below 3-d)."
    )
    normalized_coords = property(
        lambda self: self._normalized_coords, doc="Whether coordinates are normalized to [0, 1]."
    )

    @property
    def cuda_array(self) -> int:
        """Not supported: kdsl textures are no CUDA arrays."""
        raise TextureError("kdsl textures have no CUDA array: their texels are a plain "
                           "device array sampled in software")  # fmt: skip

    cuda_texture = cuda_array
    cuda_surface = cuda_array

    # -- copies -----------------------------------------------------------------------

    def _shape(self) -> tuple[int, ...]:
        """Warp's array shape of the texture's data."""
        shape = (self.depth, self.height, self.width)[3 - self._ndim:]
        return shape if self._num_channels == 1 else (*shape, self._num_channels)

    def _level0(self, what: str) -> np.ndarray:
        if self.is_mipmapped:
            raise TextureError(f"{what} is not supported for mipmapped textures; their "
                               "contents are fixed at construction")  # fmt: skip
        host = self._buffer.numpy().view(self._np_dtype)
        return host.reshape(self._shape())

    def _check_like(self, texels: np.ndarray, channels: int, what: str) -> None:
        found = (texels.shape[2], texels.shape[1], texels.shape[0], channels, texels.dtype)
        mine = (*self._size, self._num_channels, self._np_dtype)
        if found != mine:
            raise TextureError(f"incompatible {what}: texture shape {self._shape()} of "
                               f"{self._np_dtype}, got shape {found[2::-1][3 - self._ndim:]}"
                               f" with {channels} channel(s) of {texels.dtype}")  # fmt: skip

    def copy_from(self, src: Any) -> None:
        """Overwrite the texels with ``src``: a texture, a NumPy array or a kdsl array of
        the texture's shape, channels and dtype (on any device)."""
        self._level0("copy_from")
        if isinstance(src, Texture):
            src = src._level0("copy_from")
        texels, channels = parse_data(src, self._ndim)
        self._check_like(texels, channels, "source")
        self._buffer.assign(np.ascontiguousarray(texels).ravel().view(self._buffer.numpy().dtype))

    def copy_to(self, dst: Any) -> None:
        """Write the texels into ``dst``: a texture, a NumPy array or a kdsl array of the
        texture's shape, channels and dtype."""
        host = self._level0("copy_to")
        if isinstance(dst, Texture):
            dst.copy_from(host)
            return
        texels, channels = parse_data(dst, self._ndim)
        self._check_like(texels, channels, "destination")
        if isinstance(dst, np.ndarray):
            dst.reshape(-1)[...] = host.reshape(-1)
        else:
            dst.assign(host.reshape(dst.numpy().shape))

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(shape={self._shape()}, dtype={self._np_dtype}, "
                f"device='{self.device}')")  # fmt: skip


class Texture1D(Texture):
    """A 1-d texture; as a kernel parameter type, its record (``tex.width`` reads its
    width). ``texture_sample(tex, u, dtype=float)`` samples it."""

    __kdsl_type__ = S.Texture1D.__kdsl_type__
    _dims = 1

    def __init__(
        self, data: Any = None, width: int = 0, num_channels: int = 0, dtype: Any = None,
        filter_mode: Any = None, address_mode: Any = TextureAddressMode.CLAMP,
        address_mode_u: Any = None, normalized_coords: bool = True, num_mip_levels: int = 1,
        mip_filter_mode: Any = None, device: Any = None, surface_access: bool = False,
        cuda_array: int = 0,
    ) -> None:  # fmt: skip
        """See ``Texture``."""
        super().__init__(data, width, 1, 1, num_channels, dtype, filter_mode, address_mode,
                         address_mode_u, None, None, normalized_coords, num_mip_levels,
                         mip_filter_mode, device, surface_access, cuda_array)  # fmt: skip


class Texture2D(Texture):
    """A 2-d texture; as a kernel parameter type, its record (``tex.width``,
    ``tex.height``). ``texture_sample(tex, uv, dtype=float)`` samples it."""

    __kdsl_type__ = S.Texture2D.__kdsl_type__
    _dims = 2

    def __init__(
        self, data: Any = None, width: int = 0, height: int = 0, num_channels: int = 0,
        dtype: Any = None, filter_mode: Any = None,
        address_mode: Any = TextureAddressMode.CLAMP, address_mode_u: Any = None,
        address_mode_v: Any = None, normalized_coords: bool = True, num_mip_levels: int = 1,
        mip_filter_mode: Any = None, device: Any = None, surface_access: bool = False,
        cuda_array: int = 0,
    ) -> None:  # fmt: skip
        """See ``Texture``."""
        super().__init__(data, width, height, 1, num_channels, dtype, filter_mode,
                         address_mode, address_mode_u, address_mode_v, None, normalized_coords,
                         num_mip_levels, mip_filter_mode, device, surface_access,
                         cuda_array)  # fmt: skip


class Texture3D(Texture):
    """A 3-d texture; as a kernel parameter type, its record (``tex.width``,
    ``tex.height``, ``tex.depth``). ``texture_sample(tex, uvw, dtype=float)`` samples it."""

    __kdsl_type__ = S.Texture3D.__kdsl_type__
    _dims = 3
