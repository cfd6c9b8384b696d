"""Warp 1.19's experimental textures: ``Texture1D``, ``Texture2D``, ``Texture3D`` and their
modes, sampled in kernels by ``texture_sample`` (kdsl code in ``kdsl.stdlib.texture``).

This package makes the textures' device arrays and the records kernels read; the
sampling itself is standard-library code, the same on every backend.
"""

from kdsl.texture.formats import TextureError
from kdsl.texture.texture import (
    Texture,
    Texture1D,
    Texture2D,
    Texture3D,
    TextureAddressMode,
    TextureFilterMode,
    TextureResourceFlags,
)

__all__ = [
    "Texture", "Texture1D", "Texture2D", "Texture3D", "TextureAddressMode",
    "TextureFilterMode", "TextureResourceFlags",
]  # fmt: skip
