"""Warp 1.19's subscripted array types: ``array[vec3]``, ``array2d[float]``, ``indexedarray[...]``."""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslTypeError
from kdsl.ir import types as T

BACKENDS = [
    "interp",
    "cpu",
    pytest.param("cuda", marks=pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")),
]


@wp.struct
class Cloud:
    points: wp.array[wp.vec3]
    scale: float


@wp.struct
class Pair:
    a: float
    b: wp.vec2


@wp.func
def norm_at(x: wp.array[wp.vec3], i: int) -> float:
    return wp.length(x[i])


# String annotations (this file uses ``from __future__ import annotations``) are the
# form most Warp examples reach the frontend in.
@wp.kernel
def subscripted(
    x: wp.array[wp.vec3],
    out: wp.array2d[float],
    cloud: Cloud,
    cube: wp.array[float, Literal[3]],
    picked: wp.indexedarray[float],
    ints: wp.array4d[wp.int32],
):
    i = wp.tid()
    out[i, 0] = norm_at(x, i) * cloud.scale
    out[i, 1] = wp.length(cloud.points[i]) + cube[0, 0, i] + picked[i] + float(ints[0, 0, 0, i])


@wp.kernel
def spelled_out(x: wp.array(dtype=wp.vec3), out: wp.array2d(dtype=float)):
    i = wp.tid()
    out[i, 0] = wp.length(x[i])


@wp.kernel
def spelled_subscript(x: wp.array[wp.vec3], out: wp.array2d[float]):
    i = wp.tid()
    out[i, 0] = wp.length(x[i])


@pytest.mark.parametrize(
    "annotation, spelled",
    [
        (wp.array[wp.vec3], wp.array(dtype=wp.vec3)),
        (wp.array[float], wp.array(dtype=float)),
        (wp.array[float, 2], wp.array(dtype=float, ndim=2)),
        (wp.array[wp.mat33d, Literal[4]], wp.array(dtype=wp.mat33d, ndim=4)),
        (wp.array1d[int], wp.array1d(dtype=int)),
        (wp.array2d[wp.vec2h], wp.array2d(dtype=wp.vec2h)),
        (wp.array3d[wp.uint8], wp.array3d(dtype=wp.uint8)),
        (wp.array4d[float], wp.array4d(dtype=float)),
        (wp.array[Pair], wp.array(dtype=Pair)),
        (wp.indexedarray[float], wp.indexedarray(dtype=float)),
        (wp.indexedarray[wp.vec3, 2], wp.indexedarray(dtype=wp.vec3, ndim=2)),
        (wp.indexedarray3d[float], wp.indexedarray3d(dtype=float)),
    ],
)
def test_subscript_names_the_same_type_as_the_call(annotation, spelled):
    assert wp.type_of(annotation) == wp.type_of(spelled)
    assert annotation == type(annotation)(annotation.family, annotation.dtype, annotation.ndim)
    assert hash(annotation) == hash(type(annotation)(annotation.family, annotation.dtype,
                                                     annotation.ndim))  # fmt: skip


def test_repr_reads_like_the_source():
    assert repr(wp.array[wp.vec3]) == "array[vec3f]"
    assert repr(wp.array2d[float]) == "array2d[float]"
    assert repr(wp.array[float, 3]) == "array3d[float]"
    assert repr(wp.indexedarray[float, 2]) == "indexedarray[float, 2]"
    assert repr(wp.array[Any]) == "array[Any]"


def test_both_spellings_compile_to_the_same_ir():
    from kdsl.ir import print_module

    def body(kernel) -> str:
        text = print_module(kernel.build_module())
        return text.split("{", 1)[1]  # the function name carries the kernel's own hash

    assert body(spelled_out) == body(spelled_subscript)


@pytest.mark.parametrize("backend", BACKENDS)
def test_kernel_with_subscripted_annotations_runs(backend):
    device = "cuda:0" if backend == "cuda" else "cpu"
    n = 4
    pts = np.arange(3 * n, dtype=np.float32).reshape(n, 3)
    x = wp.array[wp.vec3](pts, device=device)
    out = wp.zeros((n, 2), dtype=float, device=device)
    cloud = Cloud()
    cloud.points, cloud.scale = x, 2.0
    cube = wp.full((1, 1, n), 0.5, dtype=float, device=device)
    base = wp.array(np.arange(10, dtype=np.float32), device=device)
    order = wp.array(np.array([9, 8, 7, 6], dtype=np.int32), device=device)
    picked = wp.indexedarray(base, [order])
    ints = wp.array(np.arange(n, dtype=np.int32).reshape(1, 1, 1, n), device=device)
    wp.launch(subscripted, dim=n, inputs=[x, out, cloud, cube, picked, ints], device=device,
              backend=backend)  # fmt: skip
    norms = np.linalg.norm(pts, axis=1)
    expect = np.stack([2 * norms, norms + 0.5 + np.array([9, 8, 7, 6]) + np.arange(n)], axis=1)
    np.testing.assert_allclose(out.numpy(), expect, rtol=1e-6)


def test_calling_a_subscripted_type_builds_an_array():
    a = wp.array[wp.vec3]([[1, 2, 3], [4, 5, 6]])
    assert a.dtype is wp.vec3 and a.shape == (2,) and a.ndim == 1
    b = wp.array2d[float](np.ones((2, 3)))
    assert b.dtype is wp.float32 and b.shape == (2, 3)
    c = wp.array[wp.int32, 2](shape=(3, 4))
    assert c.dtype is wp.int32 and c.shape == (3, 4)
    g = wp.array[Any](np.zeros(3, dtype=np.float64))
    assert g.dtype is wp.float64


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda: wp.array[float, 5], "ndim must be an integer from 1 to 4"),
        (lambda: wp.array[float, 0], "ndim must be an integer from 1 to 4"),
        (lambda: wp.array[float, "2"], "ndim must be an integer from 1 to 4"),
        (lambda: wp.array[float, Literal[2, 3]], "ndim must be an integer"),
        (lambda: wp.array[float, 2, 3], "expects 1 or 2 type parameters"),
        (lambda: wp.array2d[float, 2], r"array2d\[...\] expects one type parameter"),
        (lambda: wp.array[str], r"array\[str\]: .*not an array dtype"),
        (lambda: wp.indexedarray[wp.array[float]], "not supported"),
    ],
)
def test_bad_subscripts_are_clear_kdsl_errors(make, message):
    with pytest.raises(KdslTypeError, match=message):
        make()


def test_generic_subscript_needs_an_instance_to_build():
    @wp.kernel
    def generic(x: wp.array[Any]):
        x[0] = 1.0

    assert generic.is_generic
    with pytest.raises(KdslTypeError, match=r"generic .*kdsl.overload") as err:
        generic.build_module()
    assert "test_array_subscript.py" in str(err.value)


def test_struct_field_type_is_the_array_type():
    fields = dict(wp.type_of(Cloud).fields)
    assert fields["points"] == T.ArrayType(T.VectorType(3, T.F32), 1)
