"""JAX on the CPU: from_jax/to_jax zero-copy, helpers, direct launch, tracers."""

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslError, KdslLaunchError
from tests.interop.kernels import saxpy

jax = pytest.importorskip("jax")
jnp = jax.numpy


pytestmark = pytest.mark.usefixtures("jax_on_the_cpu")


def _aligned(n, dtype=np.float32, align=64):
    """A NumPy array whose data is ``align``-byte aligned (JAX shares only such CPU buffers)."""
    itemsize = np.dtype(dtype).itemsize
    raw = np.zeros(n * itemsize + align, np.uint8)
    start = (-raw.ctypes.data) % align
    return raw[start : start + n * itemsize].view(dtype)


def test_from_jax_is_zero_copy():
    j = jnp.arange(6, dtype=jnp.float32).reshape(2, 3)
    a = wp.from_jax(j, dtype=wp.vec3)
    assert a.shape == (2,) and a.dtype is wp.vec3
    assert a.ptr == j.unsafe_buffer_pointer()
    assert a[1].tolist() == [3.0, 4.0, 5.0]
    b = wp.from_jax(jnp.ones(3, dtype=jnp.int32))
    assert b.dtype is wp.int32


def test_to_jax_is_zero_copy_for_aligned_buffers():
    a = wp.array(_aligned(8), dtype=wp.float32, copy=False)
    j = wp.to_jax(a)
    assert j.unsafe_buffer_pointer() == a.ptr
    a.fill_(3.0)  # seen through JAX: the memory is shared
    assert float(j[5]) == 3.0


def test_to_jax_vector_arrays_get_inner_dims():
    a = wp.full(4, (1.0, 2.0, 3.0), dtype=wp.vec3)
    j = wp.to_jax(a)
    assert j.shape == (4, 3) and j.dtype == jnp.float32
    assert np.asarray(j)[2].tolist() == [1.0, 2.0, 3.0]


def test_round_trip_from_jax_to_jax():
    j = jnp.arange(4, dtype=jnp.float32)
    back = wp.to_jax(wp.from_jax(j))
    assert np.asarray(back).tolist() == [0.0, 1.0, 2.0, 3.0]


def test_from_jax_errors():
    with pytest.raises(TypeError, match="bfloat16 has no kdsl equivalent"):
        wp.from_jax(jnp.zeros(2, dtype=jnp.bfloat16))
    with pytest.raises(KdslError, match=r"takes a jax\.Array"):
        wp.from_jax(np.zeros(2))
    with pytest.raises(KdslError, match="last dim must be 3"):
        wp.from_jax(jnp.zeros((2, 2)), dtype=wp.vec3)
    with pytest.raises(KdslError, match="takes a kdsl array"):
        wp.to_jax(np.zeros(2))

    @jax.jit
    def traced(x):
        wp.from_jax(x)
        return x

    with pytest.raises(KdslError, match="JAX tracer"):
        traced(jnp.zeros(2))


def test_jax_arrays_launch_directly():
    x = jnp.arange(4, dtype=jnp.float32)
    y = np.ones(4, np.float32)
    wp.launch(saxpy, dim=4, inputs=[x, y, 2.0])
    assert y.tolist() == [1.0, 3.0, 5.0, 7.0]
    with pytest.raises(KdslLaunchError, match="int32 array"):
        wp.launch(saxpy, dim=4, inputs=[jnp.zeros(4, dtype=jnp.int32), y, 1.0])


def test_tracer_as_scalar_launch_argument_is_a_clear_error():
    x = np.zeros(4, np.float32)

    @jax.jit
    def f(s):
        wp.launch(saxpy, dim=4, inputs=[x, x, s])
        return s

    with pytest.raises(KdslLaunchError, match=r"argument 2 'a': got a JAX tracer .*static"):
        f(1.0)

    @jax.jit
    def g(arr):
        wp.launch(saxpy, dim=4, inputs=[arr, x, 1.0])
        return arr

    with pytest.raises(KdslLaunchError, match=r"argument 0 'x': got a JAX tracer"):
        g(jnp.zeros(4))


def test_device_helpers():
    cpu = jax.devices("cpu")[0]
    assert wp.device_from_jax(cpu) == "cpu"
    assert wp.device_to_jax("cpu") == cpu
    if not wp.is_cuda_available():
        with pytest.raises(KdslError, match="not available"):
            wp.device_to_jax("cuda:0")
    with pytest.raises(RuntimeError, match="no kdsl equivalent"):
        wp.device_from_jax(object())


@pytest.mark.parametrize(
    "wp_type, name",
    [(wp.float16, "float16"), (wp.float32, "float32"), (wp.float64, "float64"),
     (wp.int8, "int8"), (wp.int32, "int32"), (wp.int64, "int64"), (wp.uint8, "uint8"),
     (wp.uint16, "uint16"), (wp.uint32, "uint32"), (wp.uint64, "uint64"), (wp.bool, "bool")],
)  # fmt: skip
def test_dtype_helpers_round_trip(wp_type, name):
    jt = wp.dtype_to_jax(wp_type)
    assert np.dtype(jt) == np.dtype(name)
    assert wp.dtype_from_jax(jt) is wp_type
    assert wp.dtype_from_jax(np.dtype(name)) is wp_type


def test_dtype_helper_errors():
    for bad in (jnp.bfloat16, jnp.complex64):
        with pytest.raises(TypeError, match="no kdsl equivalent"):
            wp.dtype_from_jax(bad)
    with pytest.raises(TypeError, match="no JAX dtype"):
        wp.dtype_to_jax(wp.mat22)
