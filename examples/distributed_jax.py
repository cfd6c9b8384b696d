"""kdsl kernels on several JAX devices: ``shard_map`` and ``pmap`` with ``ppermute`` and ``psum``.

    python examples/distributed_jax.py              # every JAX device (GPUs where present)
    XLA_FLAGS=--xla_force_host_platform_device_count=4 JAX_PLATFORMS=cpu \\
        python examples/distributed_jax.py          # four CPU devices

A line of values is cut into one piece per device. Each smoothing step trades the
pieces' end values with the neighbouring devices (``jax.lax.ppermute``: the ghost
cells), then a kdsl kernel (``jax_kernel``) smooths the piece with its ghost cells;
at the end a second kdsl kernel sums ``u^2`` of each piece (an in-out accumulator,
since XLA's output buffers start uninitialized) and ``jax.lax.psum`` adds the pieces'
sums. The same program runs three ways: ``jax_kernel`` under ``shard_map``, under
``pmap``, and a ``jax_callable`` (a Python function launching both kernels) under
``pmap``. Each must give the one-device run's field bit for bit (the same kernels on
the same values) and its sum to rounding (added in another order).
"""

import sys
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

import kdsl as wp
from kdsl.jax_experimental import jax_callable, jax_kernel

A = 0.25  # the smoothing weight (stable: a <= 1/2)


@wp.kernel
def smooth(u: wp.array(dtype=wp.float32), a: wp.float32, out: wp.array(dtype=wp.float32)):
    # u is the piece with one ghost cell at each end: out[i] is cell u[i + 1] smoothed.
    i = wp.tid()
    out[i] = u[i + 1] + a * (u[i] - 2.0 * u[i + 1] + u[i + 2])


@wp.kernel
def sum_squares(u: wp.array(dtype=wp.float32), total: wp.array(dtype=wp.float32)):
    wp.atomic_add(total, 0, u[wp.tid()] * u[wp.tid()])


jax_smooth = jax_kernel(smooth)
jax_sum_squares = jax_kernel(sum_squares, num_outputs=1, in_out_argnames=["total"])


def with_ghost_cells(u: jax.Array, axis: str, count: int) -> jax.Array:
    """``u`` with its neighbours' end values at both ends (zeros at the line's ends)."""
    # Device k's last value becomes device k+1's left ghost, its first k-1's right ghost;
    # ppermute gives zeros to a device that no one sends to (the line's ends).
    left = jax.lax.ppermute(u[-1:], axis, [(k, k + 1) for k in range(count - 1)])
    right = jax.lax.ppermute(u[:1], axis, [(k + 1, k) for k in range(count - 1)])
    return jnp.concatenate([left, u, right])


def piece_by_kernels(u: jax.Array, axis: str, count: int, iters: int) -> tuple:
    """One device's piece: ``iters`` smoothing steps, then the global sum of ``u^2``."""
    for _ in range(iters):
        (u,) = jax_smooth(with_ghost_cells(u, axis, count), A, launch_dims=u.shape[0])
    (part,) = jax_sum_squares(u, jnp.zeros(1, jnp.float32), launch_dims=u.shape[0])
    return u, jax.lax.psum(part, axis)


def smooth_and_sum(
    padded: wp.array(dtype=wp.float32), total: wp.array(dtype=wp.float32),
    out: wp.array(dtype=wp.float32),
):  # fmt: skip
    """A Python function launching both kernels (``jax_callable``): out, and total += sum out^2."""
    n = out.shape[0]
    wp.launch(smooth, dim=n, inputs=[padded, A], outputs=[out], device=out.device)
    wp.launch(sum_squares, dim=n, inputs=[out], outputs=[total], device=out.device)


jax_smooth_and_sum = jax_callable(smooth_and_sum, num_outputs=2, in_out_argnames=["total"])


def piece_by_callable(u: jax.Array, axis: str, count: int, iters: int) -> tuple:
    """The same with one ``jax_callable`` a step (its sum is kept from the last step)."""
    for _ in range(iters):
        padded = with_ghost_cells(u, axis, count)
        part, u = jax_smooth_and_sum(padded, jnp.zeros(1, jnp.float32),
                                     output_dims={"out": u.shape[0]})  # fmt: skip
    return u, jax.lax.psum(part, axis)


def shard_map_run(u0: np.ndarray, devices: list, iters: int) -> tuple:
    """``jax_kernel`` under ``shard_map`` over ``devices``."""
    from jax.sharding import Mesh, NamedSharding
    from jax.sharding import PartitionSpec as P

    shard_map = getattr(jax, "shard_map", None)
    if shard_map is None:  # JAX before 0.7
        from jax.experimental.shard_map import shard_map
    mesh = Mesh(np.array(devices), "x")
    body = partial(piece_by_kernels, axis="x", count=len(devices), iters=iters)
    f = jax.jit(shard_map(body, mesh=mesh, in_specs=P("x"), out_specs=(P("x"), P())))
    u = jax.device_put(jnp.asarray(u0), NamedSharding(mesh, P("x")))
    field, total = f(u)
    return np.asarray(field), float(np.asarray(total)[0])


def pmap_run(u0: np.ndarray, devices: list, iters: int, piece: object) -> tuple:
    """``piece`` (either of the two above) under ``pmap`` over ``devices``."""
    body = partial(piece, axis="x", count=len(devices), iters=iters)
    f = jax.pmap(body, axis_name="x", devices=devices)
    field, total = f(jnp.asarray(u0).reshape(len(devices), -1))
    return np.asarray(field).ravel(), float(np.asarray(total)[0, 0])


def main(points_per_device: int = 256, iters: int = 8) -> int:
    """Run the three ways on every device and on one; returns the exit status."""
    devices = jax.devices()
    n = points_per_device * len(devices)
    u0 = np.random.default_rng(3).random(n).astype(np.float32)
    one_field, one_total = shard_map_run(u0, devices[:1], iters)
    ref = u0.astype(np.float64)  # NumPy, float64: the one-device run to rounding
    for _ in range(iters):
        p = np.pad(ref, 1)
        ref = p[1:-1] + A * (p[:-2] - 2.0 * p[1:-1] + p[2:])
    ok = np.allclose(one_field, ref, rtol=1e-5, atol=1e-6)
    ok = ok and np.isclose(one_total, float(np.sum(ref**2)), rtol=1e-5)
    runs = {
        "shard_map(jax_kernel)": shard_map_run(u0, devices, iters),
        "pmap(jax_kernel)": pmap_run(u0, devices, iters, piece_by_kernels),
        "pmap(jax_callable)": pmap_run(u0, devices, iters, piece_by_callable),
    }
    for name, (field, total) in runs.items():
        same = field.tobytes() == one_field.tobytes()
        close = np.isclose(total, one_total, rtol=1e-5)
        ok = ok and same and close
        print(f"{name}: {len(devices)} {devices[0].platform} devices, field bit for bit: {same}, "
              f"sum u^2 {total:.7g} (one device {one_total:.7g})")  # fmt: skip
    print("ok" if ok else "MISMATCH")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
