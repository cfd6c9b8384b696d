"""The feature analysis: its vocabulary (``Features.names``) on kernels built by the frontend."""

from __future__ import annotations

import pytest

import kdsl as wp
from kdsl.errors import KdslError
from kdsl.ir import parse_module, print_module
from kdsl.passes import CLEANUP_PIPELINE, DEFAULT_PIPELINE, run_pipeline
from kdsl.passes.features import analyze_features

#: The adjoint stage as a pipeline: the adjoint, then the cleanup that drops unread tapes.
ADJOINT = f"{DEFAULT_PIPELINE},adjoint,{CLEANUP_PIPELINE},tape-dce,{CLEANUP_PIPELINE}"


@wp.kernel
def plain(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = 2.0 * x[i]


@wp.kernel
def busy(
    q: wp.array(dtype=wp.quat),
    m: wp.array(dtype=wp.mat33),
    b: wp.array(dtype=wp.int8),
    c: wp.array2d(dtype=wp.uint64),
    y: wp.array2d(dtype=float),
):
    i, j = wp.tid()
    wp.atomic_max(c, i, j, wp.uint64(3))
    s = wp.rand_init(1, i)
    y[i, j] = wp.randf(s) + wp.noise(s, y[i, j]) + wp.sin(float(b[i]))
    q[i] = wp.normalize(q[i])
    m[i] = wp.transpose(m[i])


@wp.kernel
def looped(x: wp.array(dtype=float), n: int):
    i = wp.tid()
    s = 0.0
    for _ in range(n):
        s = wp.sin(s + x[i])
    x[i] = s


@wp.kernel
def straight(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = wp.sin(x[i])


def _names(kernel, pipeline: str = DEFAULT_PIPELINE) -> frozenset[str]:
    m = kernel.build_module()
    run_pipeline(m, pipeline)
    return analyze_features(m).names


def test_a_plain_kernel_lists_no_optional_feature():
    assert _names(plain) == frozenset()


def test_vocabulary():
    names = _names(busy)
    expected = {"int8", "int64", "atomics", "atomic.max", "math.sin", "quaternions",
                "matrices", "tid.2d", "stdlib.random", "stdlib.noise"}  # fmt: skip
    assert expected <= names
    assert not {"f16", "print", "structs", "atomic.add", "adjoint"} & names


def test_library_code_is_known_by_its_locations_only():
    m = busy.build_module()
    run_pipeline(m, DEFAULT_PIPELINE)
    assert "stdlib.noise" in analyze_features(m)
    bare = parse_module(print_module(m))  # printed without locations
    names = analyze_features(bare).names
    assert "stdlib.noise" not in names and "atomic.max" in names


def test_adjoints_and_their_tapes():
    assert "adjoint" not in _names(looped)
    assert {"adjoint", "tapes", "loops"} <= _names(looped, ADJOINT)
    names = _names(straight, ADJOINT)
    assert "adjoint" in names and "tapes" not in names


def test_require_names_the_missing_feature():
    features = analyze_features(plain.build_module())
    with pytest.raises(KdslError, match=r"'print'.*does not list"):
        features.require("print", "the printf declaration")
