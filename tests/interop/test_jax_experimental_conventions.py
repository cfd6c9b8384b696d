"""``kdsl.jax_experimental.jax_kernel`` takes Warp's FFI signature and its older one.

The older guide (Warp before 1.10) imports ``jax_kernel`` from
``warp.jax_experimental`` and calls it without ``num_outputs``: the outputs are the
parameters after the call's arguments, several of them returned together (issue 13).
"""

import numpy as np
import pytest

import kdsl as wp
from kdsl.interop.jax_ffi import JaxFfiError
from kdsl.jax_experimental import jax_kernel

jax = pytest.importorskip("jax")
jnp = jax.numpy


pytestmark = pytest.mark.usefixtures("jax_on_the_cpu")


@wp.kernel
def triple_kernel(input: wp.array(dtype=float), output: wp.array(dtype=float)):
    tid = wp.tid()
    output[tid] = 3.0 * input[tid]


@wp.kernel
def multiarg_kernel(
    a: wp.array(dtype=float),
    b: wp.array(dtype=float),
    c: wp.array(dtype=float),
    ab: wp.array(dtype=float),
    bc: wp.array(dtype=float),
):
    tid = wp.tid()
    ab[tid] = a[tid] + b[tid]
    bc[tid] = b[tid] + c[tid]


@wp.kernel
def matmul_kernel(
    a: wp.array2d(dtype=float), b: wp.array2d(dtype=float), c: wp.array2d(dtype=float)
):
    i, j = wp.tid()
    s = wp.float32(0)
    for k in range(a.shape[1]):
        s += a[i, k] * b[k, j]
    c[i, j] = s


def test_older_guide_single_output():
    jax_triple = jax_kernel(triple_kernel, quiet=True)
    (r,) = jax.jit(lambda: jax_triple(jnp.arange(0, 64, dtype=jnp.float32)))()
    np.testing.assert_allclose(np.asarray(r), 3.0 * np.arange(64))


def test_older_guide_several_outputs_inferred_from_the_kernel():
    jax_multiarg = jax_kernel(multiarg_kernel)
    x, y = jax.jit(lambda: jax_multiarg(*(jnp.full(64, v, jnp.float32) for v in (1, 2, 3))))()
    assert np.all(np.asarray(x) == 3.0) and np.all(np.asarray(y) == 5.0)


@pytest.mark.parametrize("spelling", ["keyword", "positional"])
def test_older_guide_launch_dims(spelling):
    n, m, k = 3, 4, 2
    if spelling == "keyword":
        jax_matmul = jax_kernel(matmul_kernel, launch_dims=(n, m))
    else:
        jax_matmul = jax_kernel(matmul_kernel, (n, m))  # the older second parameter
    (c,) = jax.jit(
        lambda: jax_matmul(jnp.full((n, k), 2, jnp.float32), jnp.full((k, m), 3, jnp.float32))
    )()
    assert c.shape == (n, m) and np.all(np.asarray(c) == 12.0)


def test_ffi_signature_still_works_and_checks_the_count():
    jax_multiarg = jax_kernel(multiarg_kernel, 2)  # FFI: num_outputs=2
    x, y = jax.jit(lambda: jax_multiarg(*(jnp.full(8, v, jnp.float32) for v in (1, 2, 3))))()
    assert np.all(np.asarray(x) == 3.0) and np.all(np.asarray(y) == 5.0)
    with pytest.raises(JaxFfiError, match="multiarg_kernel"):
        jax.jit(lambda: jax_multiarg(jnp.ones(8, jnp.float32)))()


def test_no_output_left_is_a_clear_error():
    jax_triple = jax_kernel(triple_kernel)
    a = jnp.ones(4, jnp.float32)
    with pytest.raises(JaxFfiError, match="at least one output"):
        jax.jit(lambda: jax_triple(a, a))()
