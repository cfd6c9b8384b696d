"""The kernels the interop tests launch on arrays from other frameworks."""

import kdsl as wp


@wp.kernel
def saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
    i = wp.tid()
    y[i] = a * x[i] + y[i]


@wp.kernel
def double_vec(v: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    v[i] = v[i] * 2.0
