"""``kdsl.examples``: where Warp's example assets are, for Warp programs that read them.

Warp's examples load meshes and volumes from ``warp.examples.get_asset_directory()``.
kdsl ships no copy of those assets: with warp-lang installed (the ``bench`` extra) these
functions point at Warp's own directory, so such programs run unchanged under
``import kdsl as wp``; without it they raise a ``KdslError`` that says what to install.
kdsl's own examples are the scripts in the repository's ``examples/`` directory.
"""

from __future__ import annotations

import importlib.util
import os

from kdsl.errors import KdslError

__all__ = ["get_asset_directory", "get_source_directory"]


def get_source_directory() -> str:
    """The directory of Warp's installed examples (``warp/examples``)."""
    spec = importlib.util.find_spec("warp")  # finds the package without importing it
    if spec is None or not spec.origin:
        raise KdslError(
            "Warp's example assets ship with warp-lang, which is not installed: "
            "pip install 'kdsl[bench]' (or warp-lang) to run programs that read them"
        )
    return os.path.realpath(os.path.join(os.path.dirname(spec.origin), "examples"))


def get_asset_directory() -> str:
    """The directory of Warp's example assets (meshes, volumes), as ``warp.examples``."""
    return os.path.join(get_source_directory(), "assets")
