"""jax_kernel / jax_callable / register_ffi_callback through XLA's FFI, on JAX's CPU.

The seed's examples ported with ``import kdsl as wp``, values checked against NumPy;
jit, vmap, static scalars, vector/matrix arrays, in-out arguments, shard_map over
two CPU devices (in a subprocess), and the errors for bad use.
"""

import math
import os
import subprocess
import sys
import textwrap
from functools import partial
from pathlib import Path

import numpy as np
import pytest

import kdsl as wp
from kdsl.interop.dtypes import InteropTypeError
from kdsl.jax_experimental.ffi import (
    GraphMode,
    JaxFfiError,
    jax_callable,
    jax_kernel,
    register_ffi_callback,
)

jax = pytest.importorskip("jax")
jnp = jax.numpy


pytestmark = pytest.mark.usefixtures("jax_on_the_cpu")


@wp.kernel
def triple_kernel(input: wp.array(dtype=float), output: wp.array(dtype=float)):
    tid = wp.tid()
    output[tid] = 3.0 * input[tid]


@wp.kernel
def add_kernel(a: wp.array(dtype=int), b: wp.array(dtype=int), output: wp.array(dtype=int)):
    tid = wp.tid()
    output[tid] = a[tid] + b[tid]


@wp.kernel
def sincos_kernel(
    angle: wp.array(dtype=float), sin_out: wp.array(dtype=float), cos_out: wp.array(dtype=float)
):
    tid = wp.tid()
    sin_out[tid] = wp.sin(angle[tid])
    cos_out[tid] = wp.cos(angle[tid])


@wp.kernel
def diagonal_kernel(output: wp.array(dtype=wp.mat33)):
    tid = wp.tid()
    output[tid] = wp.mat33(1.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 3.0)


@wp.kernel
def scale_kernel(a: wp.array(dtype=float), s: float, output: wp.array(dtype=float)):
    tid = wp.tid()
    output[tid] = a[tid] * s


@wp.kernel
def scale_vec_kernel(a: wp.array(dtype=wp.vec2), s: float, output: wp.array(dtype=wp.vec2)):
    tid = wp.tid()
    output[tid] = a[tid] * s


@wp.kernel
def matmul_kernel(
    a: wp.array2d(dtype=float), b: wp.array2d(dtype=float), c: wp.array2d(dtype=float)
):
    i, j = wp.tid()
    N = a.shape[0]
    K = a.shape[1]
    M = b.shape[1]
    if i < N and j < M:
        s = wp.float32(0)
        for k in range(K):
            s += a[i, k] * b[k, j]
        c[i, j] = s


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
def vecmat_kernel(
    a: wp.array(dtype=float),
    b: wp.array(dtype=wp.vec3),
    c: wp.array(dtype=wp.mat22),
    d: wp.array(dtype=float),
    e: wp.array(dtype=wp.vec3),
    f: wp.array(dtype=wp.mat22),
):
    tid = wp.tid()
    d[tid] = 2.0 * a[tid]
    e[tid] = b[tid] + wp.vec3(1.0, 2.0, 3.0)
    f[tid] = wp.transpose(c[tid])


@wp.kernel
def funky_kernel(a: wp.array(dtype=float), b: wp.array(dtype=float), c: wp.array(dtype=float)):
    tid = wp.tid()
    if tid < b.shape[0]:
        b[tid] = a[0] + float(tid)
    if tid < c.shape[0]:
        c[tid] = a[0] - float(tid)


@wp.kernel
def accumulate_kernel(
    x: wp.array(dtype=float), acc: wp.array(dtype=float), out: wp.array(dtype=float)
):
    tid = wp.tid()
    acc[tid] = acc[tid] + x[tid]
    out[tid] = 2.0 * x[tid]


def test_custom_call_examples():
    from kdsl.jax_experimental import custom_call

    jax_triple = custom_call.jax_kernel(triple_kernel)
    (r,) = jax.jit(lambda: jax_triple(jnp.arange(0, 64, dtype=jnp.float32)))()
    np.testing.assert_allclose(np.asarray(r), 3.0 * np.arange(64))

    jax_multiarg = custom_call.jax_kernel(multiarg_kernel)
    x, y = jax.jit(lambda: jax_multiarg(*(jnp.full(64, v, jnp.float32) for v in (1, 2, 3))))()
    assert np.all(np.asarray(x) == 3.0) and np.all(np.asarray(y) == 5.0)

    N, M, K = 3, 4, 2
    jax_matmul = custom_call.jax_kernel(matmul_kernel, launch_dims=(N, M))
    (c,) = jax.jit(
        lambda: jax_matmul(jnp.full((N, K), 2, jnp.float32), jnp.full((K, M), 3, jnp.float32))
    )()
    assert c.shape == (N, M) and np.all(np.asarray(c) == 12.0)


def test_add_and_default_jax_kernel():
    from kdsl.jax_experimental import jax_kernel as default_jax_kernel

    assert jax_kernel is wp.jax_kernel  # the FFI version; jax_experimental's takes both
    jax_add = default_jax_kernel(add_kernel)  # conventions (test_jax_experimental_conventions)

    @jax.jit
    def f():
        n = 10
        return jax_add(jnp.arange(n, dtype=jnp.int32), jnp.ones(n, dtype=jnp.int32))

    (r,) = f()
    assert r.dtype == jnp.int32
    np.testing.assert_array_equal(np.asarray(r), np.arange(10) + 1)


def test_sincos_two_outputs():
    jax_sincos = jax_kernel(sincos_kernel, num_outputs=2)
    s, c = jax.jit(lambda: jax_sincos(jnp.linspace(0, 2 * math.pi, 32)))()
    angle = np.linspace(0, 2 * math.pi, 32, dtype=np.float32)
    np.testing.assert_allclose(np.asarray(s), np.sin(angle), atol=1e-6)
    np.testing.assert_allclose(np.asarray(c), np.cos(angle), atol=1e-6)


def test_no_inputs_matrix_output():
    jax_diagonal = jax_kernel(diagonal_kernel)
    (r,) = jax.jit(lambda: jax_diagonal(launch_dims=4))()
    assert r.shape == (4, 3, 3)
    np.testing.assert_array_equal(
        np.asarray(r), np.broadcast_to(np.diag([1.0, 2.0, 3.0]), (4, 3, 3))
    )


def test_static_scalars():
    jax_scale = jax_kernel(scale_kernel)
    a = jnp.arange(10, dtype=jnp.float32)
    (r,) = jax.jit(lambda: jax_scale(jnp.arange(10, dtype=jnp.float32), 2.0))()
    np.testing.assert_array_equal(np.asarray(r), 2.0 * np.arange(10))

    with pytest.raises(JaxFfiError, match=r"'s'.*traced value.*static_argnames"):
        jax.jit(lambda a, s: jax_scale(a, s))(a, 2.0)

    f = jax.jit(lambda a, s: jax_scale(a, s), static_argnames=["s"])
    for s in (2.0, 3.0, 2.0):  # each static value is baked into its own trace
        np.testing.assert_array_equal(np.asarray(f(a, s=s)[0]), s * np.arange(10))
    np.testing.assert_array_equal(np.asarray(partial(f, s=0.5)(a)[0]), 0.5 * np.arange(10))


def test_per_call_launch_dims():
    jax_matmul = jax_kernel(matmul_kernel)

    @jax.jit
    def f():
        a1, b1 = jnp.full((3, 2), 2, jnp.float32), jnp.full((2, 4), 3, jnp.float32)
        a2, b2 = jnp.full((4, 2), 2, jnp.float32), jnp.arange(6, dtype=jnp.float32).reshape(2, 3)
        return jax_matmul(a1, b1, launch_dims=(3, 4))[0], jax_matmul(a2, b2, launch_dims=(4, 3))[0]

    r1, r2 = f()
    np.testing.assert_array_equal(np.asarray(r1), np.full((3, 4), 12.0))
    np.testing.assert_array_equal(
        np.asarray(r2), np.full((4, 2), 2.0) @ np.arange(6.0).reshape(2, 3)
    )


def test_output_dims():
    jax_funky = jax_kernel(funky_kernel, num_outputs=2)
    a = jnp.full(8, 10.0, jnp.float32)
    b, c = jax_funky(a, output_dims=5)
    assert b.shape == c.shape == (5,)
    b, c = jax_funky(a, output_dims={"b": 3, "c": (6,)})
    np.testing.assert_array_equal(np.asarray(b), 10.0 + np.arange(3))
    np.testing.assert_array_equal(np.asarray(c), 10.0 - np.arange(6))
    b, c = jax.jit(lambda a: jax_funky(a, launch_dims=2, output_dims={"b": 4, "c": 2}))(a)
    assert b.shape == (4,) and np.asarray(b)[:2].tolist() == [10.0, 11.0]
    np.testing.assert_array_equal(np.asarray(c), [10.0, 9.0])


def test_vector_and_matrix_arrays():
    jax_vecmat = jax_kernel(vecmat_kernel, num_outputs=3)
    n = 10
    a = jnp.arange(n, dtype=jnp.float32)
    b = jnp.arange(3 * n, dtype=jnp.float32).reshape(n, 3)
    c = jnp.arange(4 * n, dtype=jnp.float32).reshape(n, 2, 2)
    want = (2.0 * np.asarray(a), np.asarray(b) + [1, 2, 3], np.asarray(c).transpose(0, 2, 1))
    for dims in (None, n, {"d": n, "e": n, "f": n}, {"d": n, "e": (n, 3), "f": (n, 2, 2)},
                 {"d": a.shape, "e": b.shape, "f": c.shape}):  # fmt: skip
        d, e, f = jax.jit(lambda a, b, c, dims=dims: jax_vecmat(a, b, c, output_dims=dims))(a, b, c)
        assert (d.shape, e.shape, f.shape) == ((n,), (n, 3), (n, 2, 2))
        for got, w in zip((d, e, f), want):
            np.testing.assert_array_equal(np.asarray(got), w)


def test_vmap_methods():
    jax_add = jax_kernel(add_kernel)
    x = jnp.arange(12, dtype=jnp.int32).reshape(3, 4)
    y = jnp.ones((3, 4), jnp.int32)
    want = np.asarray(x) + 1
    (r,) = jax.jit(jax.vmap(jax_add))(x, y)
    np.testing.assert_array_equal(np.asarray(r), want)
    for method in ("sequential", "expand_dims", "broadcast_all"):
        (r,) = jax.vmap(lambda a, b, m=method: jax_add(a, b, vmap_method=m))(x, y)
        np.testing.assert_array_equal(np.asarray(r), want)
    # a broadcast (unbatched) operand, and two levels of batching
    (r,) = jax.vmap(jax_add, in_axes=(0, None))(x, y[0])
    np.testing.assert_array_equal(np.asarray(r), want)
    x3 = jnp.arange(24, dtype=jnp.int32).reshape(2, 3, 4)
    (r,) = jax.vmap(jax.vmap(jax_add))(x3, x3)
    np.testing.assert_array_equal(np.asarray(r), 2 * np.asarray(x3))
    # a kernel that is not element-wise needs "sequential"
    seq = jax_kernel(matmul_kernel, vmap_method="sequential")
    a = jnp.arange(12, dtype=jnp.float32).reshape(2, 3, 2)
    b = jnp.ones((2, 2, 4), jnp.float32)
    (r,) = jax.vmap(lambda a, b: seq(a, b, launch_dims=(3, 4)))(a, b)
    np.testing.assert_allclose(np.asarray(r), np.asarray(a) @ np.asarray(b))


def test_in_out_argnames():
    jax_acc = jax_kernel(accumulate_kernel, num_outputs=2, in_out_argnames=["acc"])
    x = jnp.arange(5, dtype=jnp.float32)
    acc = jnp.full(5, 100.0, jnp.float32)
    acc2, out = jax.jit(jax_acc)(x, acc)
    np.testing.assert_array_equal(np.asarray(acc2), 100.0 + np.arange(5))
    np.testing.assert_array_equal(np.asarray(out), 2.0 * np.arange(5))
    np.testing.assert_array_equal(np.asarray(acc), np.full(5, 100.0))  # JAX's input unchanged


def test_jax_callable_seed_example():
    def example_func(
        a: wp.array(dtype=float),
        b: wp.array(dtype=wp.vec2),
        s: float,
        c: wp.array(dtype=float),
        d: wp.array(dtype=wp.vec2),
    ):
        wp.launch(scale_kernel, dim=a.shape, inputs=[a, s], outputs=[c])
        wp.launch(scale_vec_kernel, dim=b.shape, inputs=[b, s], outputs=[d])

    for mode in (GraphMode.JAX, GraphMode.KDSL, GraphMode.NONE):
        jax_func = jax_callable(example_func, num_outputs=2, graph_mode=mode)

        @jax.jit
        def f(jax_func=jax_func):
            a = jnp.arange(10, dtype=jnp.float32)
            b = jnp.arange(10, dtype=jnp.float32).reshape((5, 2))
            return jax_func(a, b, 2.0, output_dims={"c": a.shape, "d": b.shape})

        c, d = f()
        np.testing.assert_array_equal(np.asarray(c), 2.0 * np.arange(10))
        np.testing.assert_array_equal(np.asarray(d), 2.0 * np.arange(10).reshape(5, 2))
    assert GraphMode.WARP is GraphMode.KDSL
    assert wp.jax_callable is jax_callable


def test_jax_callable_sees_jax_buffers_without_copy():
    seen = {}

    def probe(a: wp.array(dtype=float), out: wp.array(dtype=float)):
        seen["ptr"], seen["shape"], seen["device"] = a.ptr, a.shape, a.device
        wp.launch(scale_kernel, dim=a.shape, inputs=[a, 1.0], outputs=[out])

    x = jnp.arange(64, dtype=jnp.float32)
    (r,) = jax_callable(probe)(x)  # output dims default to the first input's
    np.testing.assert_array_equal(np.asarray(r), np.arange(64))
    assert seen == {
        "ptr": x.unsafe_buffer_pointer(),
        "shape": (64,),
        "device": wp.get_device("cpu"),
    }


def test_jax_callable_errors_reach_jax():
    def broken(a: wp.array(dtype=float), out: wp.array(dtype=float)):
        raise RuntimeError("broken on purpose")

    with pytest.raises(Exception, match="broken on purpose"):
        jax.block_until_ready(jax_callable(broken)(jnp.zeros(4, jnp.float32)))


def test_register_ffi_callback_seed_example():
    def kdsl_func(inputs, outputs, attrs, ctx):
        a, b = inputs
        c, d = outputs
        s = attrs["scale"]
        assert ctx.device == wp.get_device("cpu") and ctx.stream == 0
        wp.launch(scale_kernel, dim=a.shape, inputs=[a, s], outputs=[c], device=ctx.device)
        wp.launch(scale_vec_kernel, dim=b.shape[0], inputs=[b, s], outputs=[d], device=ctx.device)

    register_ffi_callback("kdsl_test_func", kdsl_func)
    n = 10
    a = jnp.arange(n, dtype=jnp.float32)
    b = jnp.arange(n, dtype=jnp.float32).reshape((n // 2, 2))
    out_types = [
        jax.ShapeDtypeStruct(a.shape, jnp.float32),
        jax.ShapeDtypeStruct(b.shape, jnp.float32),
    ]
    c, d = jax.ffi.ffi_call("kdsl_test_func", out_types)(a, b, scale=2.0)
    np.testing.assert_array_equal(np.asarray(c), 2.0 * np.arange(n))
    np.testing.assert_array_equal(np.asarray(d), 2.0 * np.arange(n).reshape(5, 2))


def test_bad_use_is_a_clear_kdsl_error():
    with pytest.raises(JaxFfiError, match="num_outputs=4 but it has only 3 parameters"):
        jax_kernel(add_kernel, num_outputs=4)
    with pytest.raises(JaxFfiError, match=r"output 's' is a f32.*is num_outputs=2 right"):
        jax_kernel(scale_kernel, num_outputs=2)
    with pytest.raises(JaxFfiError, match="num_outputs must be an int >= 1"):
        jax_kernel(add_kernel, num_outputs=0)
    with pytest.raises(JaxFfiError, match="in_out_argnames names no parameter"):
        jax_kernel(add_kernel, in_out_argnames=["nope"])
    with pytest.raises(JaxFfiError, match=r"takes a @kdsl.kernel"):
        jax_kernel(lambda x: x)
    with pytest.raises(JaxFfiError, match="needs a type annotation"):
        jax_callable(lambda x: x)
    jax_add = jax_kernel(add_kernel)
    a = jnp.arange(4, dtype=jnp.int32)
    with pytest.raises(JaxFfiError, match=r"expected 2 input\(s\) \(a, b\), got 3"):
        jax_add(a, a, a)
    with pytest.raises(JaxFfiError, match=r"argument 'b' must be a JAX array.*got float"):
        jax_add(a, 1.0)
    with pytest.raises(InteropTypeError, match=r"must have dtype int32.*got float32"):
        jax_add(a, a.astype(jnp.float32))
    with pytest.raises(InteropTypeError, match="bfloat16 has no kdsl equivalent"):
        jax_add(a, a.astype(jnp.bfloat16))
    with pytest.raises(JaxFfiError, match="needs a JAX array with 1 dims, got shape"):
        jax_add(a, a.reshape(2, 2))
    with pytest.raises(JaxFfiError, match="no array input to infer the launch dims"):
        jax_kernel(diagonal_kernel)()
    with pytest.raises(JaxFfiError, match="output_dims has no entry for output 'c'"):
        jax_kernel(funky_kernel, num_outputs=2)(a.astype(jnp.float32), output_dims={"b": 2})
    with pytest.raises(JaxFfiError, match=r"argument 's'.*expected"):
        jax_kernel(scale_kernel)(a.astype(jnp.float32), "two")


_SHARD_MAP = textwrap.dedent(
    """
    import numpy as np, jax, jax.numpy as jnp
    from jax.sharding import PartitionSpec as P
    import kdsl as wp
    from kdsl.jax_experimental import jax_kernel

    @wp.kernel
    def multiply_by_two_kernel(a_in: wp.array(dtype=wp.float32), a_out: wp.array(dtype=wp.float32)):
        index = wp.tid()
        a_out[index] = a_in[index] * 2.0

    jax_warp_multiply = jax_kernel(multiply_by_two_kernel)
    shard_map = getattr(jax, "shard_map", None)
    if shard_map is None:
        from jax.experimental.shard_map import shard_map
    devices = jax.devices()
    mesh = jax.sharding.Mesh(np.array(devices), "x")
    spec = jax.sharding.NamedSharding(mesh, P("x"))
    n = len(devices) * 5
    data = jnp.arange(n, dtype=jnp.float32)
    arrays = [jax.device_put(data[idx], d)
              for d, idx in spec.addressable_devices_indices_map((n,)).items()]
    sharded = jax.make_array_from_single_device_arrays((n,), spec, arrays)
    op = shard_map(lambda a: jax_warp_multiply(a)[0], mesh=mesh, in_specs=(P("x"),),
                   out_specs=P("x"))
    result = jax.jit(op)(sharded)
    assert len(result.sharding.device_set) == len(devices), result.sharding
    np.testing.assert_array_equal(np.asarray(result), 2.0 * np.arange(n))
    print("ok", len(devices))
    """
)


def test_shard_map_over_devices(tmp_path):
    """The seed's shard_map example: two CPU devices here, every GPU on the GPU machine."""
    script = tmp_path / "shard_map_example.py"  # kernels need a source file
    script.write_text(_SHARD_MAP)
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2")
    root = str(Path(wp.__file__).resolve().parents[1])  # kdsl importable without installing
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [root, env.get("PYTHONPATH")]))
    if not any(d.platform == "gpu" for d in jax.devices()):
        env["JAX_PLATFORMS"] = "cpu"
    out = subprocess.run([sys.executable, str(script)], env=env, capture_output=True,
                         text=True, timeout=120)  # fmt: skip
    assert out.returncode == 0, out.stderr[-3000:]
    gpus = sum(d.platform == "gpu" for d in jax.devices())
    assert out.stdout.split() == ["ok", str(gpus or 2)], out.stdout


def _jax_gpu():
    try:
        return jax.devices("gpu")[0]
    except RuntimeError:
        return None


@pytest.mark.skipif(_jax_gpu() is None, reason="needs JAX with a GPU")
def test_gpu_kernel_callable_and_callback():
    """The cuda path: XLA's buffers and stream, each GraphMode, and a bare callback."""
    with jax.default_device(_jax_gpu()):
        jax_add = jax_kernel(add_kernel)
        x = jnp.arange(1000, dtype=jnp.int32)
        for _ in range(3):  # replays of XLA's CUDA graph
            (r,) = jax.jit(jax_add)(x, x)
            np.testing.assert_array_equal(np.asarray(r), 2 * np.arange(1000))
        (r,) = jax.jit(jax.vmap(jax_add))(x.reshape(10, 100), x.reshape(10, 100))
        np.testing.assert_array_equal(np.asarray(r).ravel(), 2 * np.arange(1000))

        def twice(a: wp.array(dtype=float), out: wp.array(dtype=float)):
            assert a.device.is_cuda
            wp.launch(scale_kernel, dim=a.shape, inputs=[a, 2.0], outputs=[out])

        a = jnp.arange(256, dtype=jnp.float32)
        for mode in (GraphMode.JAX, GraphMode.KDSL, GraphMode.NONE):
            f = jax.jit(jax_callable(twice, graph_mode=mode))
            for k in range(3):
                (r,) = f(a + k)
                np.testing.assert_array_equal(np.asarray(r), 2.0 * (np.arange(256) + k))

        def cb(inputs, outputs, attrs, ctx):
            assert ctx.device.is_cuda and ctx.stream is not None
            with wp.ScopedStream(wp.Stream(ctx.device, cuda_stream=ctx.stream), sync_enter=False):
                wp.launch(scale_kernel, dim=inputs[0].shape, inputs=[inputs[0], attrs["s"]],
                          outputs=[outputs[0]], device=ctx.device)  # fmt: skip

        register_ffi_callback("kdsl_test_gpu_cb", cb)
        call = jax.ffi.ffi_call("kdsl_test_gpu_cb", jax.ShapeDtypeStruct(a.shape, a.dtype))
        np.testing.assert_array_equal(np.asarray(call(a, s=3.0)), 3.0 * np.arange(256))
