"""Warp's type queries in ``kdsl.types`` (``types_equal``, ``type_is_float`` ...): the
values kernel factories test in ``wp.static(...)`` conditions."""

import pytest

import kdsl as wp
from tests.frontend.located_errors import expect_error_at_marker

QUERIES = [
    "type_is_scalar", "type_is_float", "type_is_int", "type_is_vector", "type_is_matrix",
    "type_is_quaternion", "type_is_transformation", "type_size", "type_size_in_bytes",
]  # fmt: skip
TYPES = [
    "bool", "int8", "uint8", "int16", "int32", "uint32", "int64", "uint64", "float16",
    "float32", "float64", "bfloat16", "vec3", "vec2d", "vec4i", "mat22", "mat33d", "quat",
    "quatd", "transform", "spatial_vector", "spatial_matrix",
]  # fmt: skip


def test_known_answers():
    t = wp.types
    assert t.types_equal(float, wp.float32) and t.types_equal(int, wp.int32)
    assert t.types_equal(wp.vec3, wp.vec3f) and not t.types_equal(wp.vec3, wp.vec3d)
    assert not t.types_equal(wp.quat, wp.vec4) and not t.types_equal(wp.float32, "float32")
    assert t.type_is_float(float) and t.type_is_float(wp.float16) and not t.type_is_float(int)
    assert t.type_is_int(wp.uint8) and not t.type_is_int(wp.bool) and not t.type_is_int(float)
    assert not t.type_is_scalar(wp.bool) and not t.type_is_scalar(wp.vec3)
    assert t.type_is_vector(wp.spatial_vector) and not t.type_is_vector(wp.quat)
    assert t.type_is_matrix(wp.mat33) and t.type_is_quaternion(wp.quatd)
    assert t.type_is_transformation(wp.transformd) and not t.type_is_vector(wp.transform)
    assert (t.type_size(wp.mat33), t.type_size(wp.transform), t.type_size(float)) == (9, 7, 1)
    assert (t.type_size_in_bytes(wp.vec3d), t.type_size_in_bytes(wp.bool)) == (24, 1)
    assert not t.type_is_float("float") and not t.type_is_matrix(None)


def test_size_of_a_non_value_type_is_a_clear_error():
    with pytest.raises(TypeError, match="type_size\\(\\) takes a scalar, vector or matrix"):
        wp.types.type_size(wp.array(dtype=float))


@wp.kernel
def k_bad_query(a: wp.array(dtype=float)):
    i = wp.tid()
    if wp.static(wp.types.type_size(a) > 1):  # <-
        a[i] = 1.0


def test_a_failing_query_in_static_is_located():
    expect_error_at_marker(k_bad_query, "static() expression failed: NameError")


@pytest.mark.parametrize("query", ["types_equal", *QUERIES])
def test_side_by_side_with_warp(query):
    warp = pytest.importorskip("warp")
    names = [n for n in TYPES if hasattr(warp, n)]
    pairs = [(getattr(warp, n), getattr(wp, n)) for n in names] + [(float, float), (int, int)]
    for w, k in pairs:
        if query == "types_equal":
            for w2, k2 in pairs:
                assert warp.types.types_equal(w, w2) == wp.types.types_equal(k, k2), (w, w2)
            continue
        assert getattr(warp.types, query)(w) == getattr(wp.types, query)(k), (query, w)
