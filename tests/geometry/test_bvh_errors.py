"""Bad ``kdsl.Bvh`` arguments: clear kdsl errors, never a crash."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslError, KdslTypeError
from kdsl.geometry.bvh import BvhError


def boxes(n: int = 4):
    c = np.random.default_rng(0).random((n, 3)).astype(np.float32)
    return wp.array(c, dtype=wp.vec3), wp.array(c + 0.1, dtype=wp.vec3)


def test_boxes_of_wrong_dtype_shape_or_ndim():
    lo, hi = boxes()
    with pytest.raises(KdslTypeError, match=r"lowers must be a 1-d kdsl\.array of vec3"):
        wp.Bvh(wp.zeros(4, dtype=wp.vec3d), hi)
    with pytest.raises(KdslTypeError, match=r"uppers must be a 1-d kdsl\.array of vec3"):
        wp.Bvh(lo, wp.zeros((4, 2), dtype=wp.vec3))
    with pytest.raises(KdslTypeError, match="lowers must be"):
        wp.Bvh(np.zeros((4, 3), np.float32), hi)
    with pytest.raises(KdslTypeError, match="differ in length"):
        wp.Bvh(lo, wp.zeros(3, dtype=wp.vec3))


def test_groups_of_wrong_length_dtype_or_sign():
    lo, hi = boxes()
    with pytest.raises(KdslTypeError, match=r"groups must be a 1-d kdsl\.array of int32"):
        wp.Bvh(lo, hi, groups=wp.zeros(4, dtype=wp.int64))
    with pytest.raises(KdslTypeError, match="3 entries for 4 boxes"):
        wp.Bvh(lo, hi, groups=wp.zeros(3, dtype=wp.int32))
    with pytest.raises(BvhError, match="groups must be >= 0"):
        wp.Bvh(lo, hi, groups=wp.array([0, 1, -1, 0], dtype=wp.int32))


def test_unknown_constructor_and_bad_leaf_size():
    lo, hi = boxes()
    with pytest.raises(BvhError, match="unknown BVH constructor 'octree'"):
        wp.Bvh(lo, hi, constructor="octree")
    bvh = wp.Bvh(lo, hi)
    with pytest.raises(BvhError, match="unknown BVH constructor"):
        bvh.rebuild("octree")
    with pytest.raises(BvhError, match="leaf_size must be at least 1"):
        wp.Bvh(lo, hi, leaf_size=0)
    with pytest.raises(KdslTypeError, match="leaf_size must be an int"):
        wp.Bvh(lo, hi, leaf_size=2.5)
    assert issubclass(BvhError, KdslError) and issubclass(BvhError, RuntimeError)


@pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")
def test_boxes_and_groups_on_different_devices():
    lo, hi = boxes()
    with pytest.raises(KdslTypeError, match="different devices"):
        wp.Bvh(lo, wp.zeros(4, dtype=wp.vec3, device="cuda:0"))
    with pytest.raises(KdslTypeError, match="groups is on"):
        wp.Bvh(lo, hi, groups=wp.zeros(4, dtype=wp.int32, device="cuda:0"))
