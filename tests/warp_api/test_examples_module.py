"""``kdsl.examples``: Warp's example asset directory, as ``warp.examples`` gives it."""

from __future__ import annotations

import importlib.util
import os

import pytest

import kdsl.examples
from kdsl.errors import KdslError


@pytest.mark.skipif(importlib.util.find_spec("warp") is None, reason="warp-lang not installed")
def test_asset_directory_is_warps():
    import warp.examples

    assert kdsl.examples.get_asset_directory() == os.path.realpath(
        warp.examples.get_asset_directory()
    )
    assert os.path.isdir(kdsl.examples.get_asset_directory())


def test_without_warp_the_error_says_what_to_install(monkeypatch):
    monkeypatch.setattr(importlib.util, "find_spec", lambda name: None)
    with pytest.raises(KdslError, match="pip install 'kdsl\\[bench\\]'"):
        kdsl.examples.get_asset_directory()
