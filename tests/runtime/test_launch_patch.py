"""Patchable launches: a launch whose arrays recur but whose scalars change (a time
step) reuses its packed arrays and has the new by-value arguments written in place.

Each test checks what the kernel sees against values computed here, on every launch,
and that the patched path was taken (``reuse.patches``, ``reuse.hits``) where the
backend prepares launches (cpu, cuda; interp packs nothing and must stay right).
"""

import threading
from types import SimpleNamespace

import numpy as np
import pytest

import kdsl as wp
from kdsl.backends.cpu.abi import ArgPacker
from kdsl.backends.cuda.params import Packer
from kdsl.ir import types as T
from kdsl.runtime import launch_reuse
from kdsl.runtime.launch import launch_plan

DEVICES = [
    pytest.param(("cpu", "cpu"), id="cpu"),
    pytest.param(("cpu", "interp"), id="interp"),
    pytest.param(
        ("cuda:0", None), id="cuda",
        marks=pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device"),
    ),
]  # fmt: skip


def _launch(kernel, dim, inputs, where):
    device, backend = where
    wp.launch(kernel, dim=dim, inputs=inputs, device=device, backend=backend)


def _reuse(kernel, where):
    return launch_plan(kernel, where[0], where[1]).reuse


def _prepares(where):
    return where[1] != "interp"


@wp.kernel
def every_kind(
    i8: wp.int8, u8: wp.uint8, i16: wp.int16, u16: wp.uint16, i32: wp.int32, u32: wp.uint32,
    i64: wp.int64, u64: wp.uint64, h: wp.float16, f: wp.float32, d: wp.float64, b: wp.bool,
    v: wp.vec3, m: wp.mat22, q: wp.quat, out: wp.array(dtype=wp.float64),
):  # fmt: skip
    out[0] = wp.float64(i8)
    out[1] = wp.float64(u8)
    out[2] = wp.float64(i16)
    out[3] = wp.float64(u16)
    out[4] = wp.float64(i32)
    out[5] = wp.float64(u32)
    out[6] = wp.float64(i64)
    out[7] = wp.float64(u64)
    out[8] = wp.float64(h)
    out[9] = wp.float64(f)
    out[10] = d
    out[11] = wp.where(b, wp.float64(1.0), wp.float64(0.0))
    out[12] = wp.float64(v[0])
    out[13] = wp.float64(v[2])
    out[14] = wp.float64(m[0, 1])
    out[15] = wp.float64(m[1, 0])
    out[16] = wp.float64(q[1])
    out[17] = wp.float64(q[3])


def _kinds_args(k):
    """Arguments of ``every_kind`` for step ``k`` (each value changes with k) and the
    values the kernel must see."""
    f = 0.25 + k
    args = [
        np.int8(-k), np.uint8(200 + k), np.int16(-3000 - k), np.uint16(60000 + k), -70000 - k,
        np.uint32(4_000_000_000 + k), np.int64(-(2**40) - k), np.uint64(2**63 + k),
        np.float16(1.5 + k), f, np.float64(1e300 / (k + 1)), k % 2 == 1,
        wp.vec3(f, 0.0, -f), wp.mat22(0.0, 2.0 * f, -3.0 * f, 0.0),
        wp.quat(0.0, 0.5 * f, 0.0, 0.125 * f),
    ]  # fmt: skip
    want = [float(a) for a in args[:11]] + [float(k % 2)]
    want[5] = float(np.float64(np.uint32(4_000_000_000 + k)))
    want[7] = float(np.float64(np.uint64(2**63 + k)))
    want[9] = float(np.float32(f))
    want += [f, -f, 2.0 * f, -3.0 * f, 0.5 * f, 0.125 * f]
    return args, want


@pytest.mark.parametrize("where", DEVICES)
def test_scalars_of_every_kind_changing_at_every_launch(where):
    out = wp.zeros(18, dtype=wp.float64, device=where[0])
    hits = _reuse(every_kind, where).hits
    for k in range(8):
        args, want = _kinds_args(k)
        _launch(every_kind, 1, [*args, out], where)
        np.testing.assert_array_equal(out.numpy(), want, err_msg=f"step {k}")
    reuse = _reuse(every_kind, where)
    if _prepares(where):  # one patchable launch served steps 2 to 8
        assert len(reuse.patches) == 1 and reuse.hits >= hits + 6


@wp.kernel
def advance(t: float, scale: wp.vec3, x: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    out[i] = x[i] * t + scale


@wp.kernel
def pull(s: float, n: int, out: wp.array(dtype=wp.vec3), x: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    x[i] = out[i] * s + wp.vec3(float(n), 0.0, 0.0)


@pytest.mark.parametrize("where", DEVICES)
def test_two_kernels_sharing_arrays_with_interleaved_scalars(where):
    dev = where[0]
    host = np.arange(12, dtype=np.float32).reshape(4, 3) * 0.125
    x = wp.array(host, dtype=wp.vec3, device=dev)
    out = wp.zeros(4, dtype=wp.vec3, device=dev)
    for k in range(12):
        t, s = 1.0 + 0.001 * k, 0.5 - 0.01 * k
        scale = wp.vec3(0.25 * k, -1.0, 0.0)
        _launch(advance, 4, [t, scale, x, out], where)
        o = host * np.float32(t) + np.array([0.25 * k, -1.0, 0.0], np.float32)
        np.testing.assert_allclose(out.numpy(), o, rtol=1e-6, err_msg=f"advance, step {k}")
        _launch(pull, 4, [s, k, out, x], where)
        host = (o * np.float32(s) + np.array([k, 0.0, 0.0], np.float32)).astype(np.float32)
        np.testing.assert_allclose(x.numpy(), host, rtol=1e-6, err_msg=f"pull, step {k}")
    if _prepares(where):
        assert len(_reuse(advance, where).patches) == 1 and len(_reuse(pull, where).patches) == 1


@wp.kernel
def set_to(t: float, out: wp.array(dtype=float)):
    out[wp.tid()] = t


@wp.kernel
def put_vec(v: wp.vec3, out: wp.array(dtype=wp.vec3)):
    out[0] = v


@pytest.mark.parametrize("where", DEVICES)
def test_a_vector_mutated_in_place_or_replaced_is_seen(where):
    out = wp.zeros(1, dtype=wp.vec3, device=where[0])
    v = wp.vec3(1.0, 2.0, 3.0)
    for k in range(6):
        if k % 2:
            v[1] = float(k)  # the same object, a new value
        else:
            v = wp.vec3(float(k), 2.0, 3.0)  # a new object
        _launch(put_vec, 1, [v, out], where)
        assert out.numpy()[0].tolist() == v.tolist(), f"step {k}"
    for k in range(3):  # a tuple for the vector: converted like any other value
        _launch(put_vec, 1, [(k, -1.0, 0.5), out], where)
        assert out.numpy()[0].tolist() == [k, -1.0, 0.5]


@pytest.mark.parametrize("where", DEVICES)
def test_arrays_swapped_between_patched_launches(where):
    dev = where[0]
    a, b = wp.zeros(3, dtype=float, device=dev), wp.zeros(3, dtype=float, device=dev)
    for k in range(10):
        target = a if k % 3 else b  # a patchable launch per array, each with its own t
        t = 0.5 * k + 0.25
        _launch(set_to, 3, [t, target], where)
        assert target.numpy().tolist() == [t] * 3, f"step {k}"
    assert a.numpy().tolist() == [4.25] * 3 and b.numpy().tolist() == [4.75] * 3
    c = wp.zeros(5, dtype=float, device=dev)  # another array, another size and grid
    for k in range(3):
        _launch(set_to, 5, [float(k), c], where)
        assert c.numpy().tolist() == [float(k)] * 5
    del a
    d = wp.zeros(3, dtype=float, device=dev)  # maybe where ``a`` was: a new patchable launch
    for k in range(3):
        _launch(set_to, 3, [k + 0.5, d], where)
        assert d.numpy().tolist() == [k + 0.5] * 3
    if _prepares(where):
        assert 3 <= len(_reuse(set_to, where).patches) <= 4


@wp.kernel
def set_first(t: float, out: wp.array(dtype=float)):
    out[0] = t


@pytest.mark.parametrize("where", DEVICES)
def test_distinct_scalars_do_not_grow_the_tables(where):
    out = wp.zeros(1, dtype=float, device=where[0])
    for k in range(3 * launch_reuse.MAX_SEEN):
        _launch(set_first, 1, [k * 0.5 + 0.25, out], where)
    assert out.numpy()[0] == (3 * launch_reuse.MAX_SEEN - 1) * 0.5 + 0.25
    reuse = _reuse(set_first, where)
    assert len(reuse.seen) <= launch_reuse.MAX_SEEN
    assert len(reuse.entries) <= 1 and len(reuse.known) <= 1
    assert len(reuse.patches) == (1 if _prepares(where) else 0)


def test_distinct_arrays_do_not_grow_the_patches_beyond_their_bound(monkeypatch):
    monkeypatch.setattr(launch_reuse, "MAX_PATCHES", 4)
    outs = [wp.zeros(1, dtype=float, device="cpu") for _ in range(10)]
    for k in range(3):
        for j, o in enumerate(outs):
            wp.launch(set_to, 1, inputs=[k + 0.01 * j, o], device="cpu", backend="cpu")
    assert [o.numpy()[0] for o in outs] == [np.float32(2 + 0.01 * j) for j in range(10)]
    assert len(_reuse(set_to, ("cpu", "cpu")).patches) <= 4


@wp.kernel
def scaled(t: float, x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = x[i] * t * t


@pytest.mark.parametrize("where", DEVICES[:2])
def test_adjoints_with_a_changing_scalar(where):
    """An adjoint launch (the general path, no ``relaunch``) is patched as well."""
    x = wp.array(np.arange(4, dtype=np.float32), device=where[0], requires_grad=True)
    y = wp.zeros(4, dtype=float, device=where[0], requires_grad=True)
    for k in range(6):
        t = 1.0 + 0.5 * k
        tape = wp.Tape()
        with tape:
            _launch(scaled, 4, [t, x, y], where)
        tape.backward(grads={y: wp.array(np.ones(4, np.float32), device=where[0])})
        np.testing.assert_allclose(x.grad.numpy(), np.full(4, t * t), rtol=1e-6)
        tape.zero()


def test_another_thread_never_writes_a_patchable_launch_it_does_not_own():
    out = wp.zeros(2, dtype=float, device="cpu")
    for k in range(3):
        wp.launch(set_to, 2, inputs=[float(k), out], device="cpu", backend="cpu")
    reuse = _reuse(set_to, ("cpu", "cpu"))
    (patch,) = [p for p in reuse.patches.values() if p.refs[0]() is out._buf]
    seen, written = [], []
    write = patch.write
    patch.write = lambda values: (written.append(threading.get_ident()), write(values))[1]

    def other() -> None:
        for k in range(5):
            wp.launch(set_to, 2, inputs=[10.0 + k, out], device="cpu", backend="cpu")
            seen.append(out.numpy().tolist())

    th = threading.Thread(target=other)
    th.start()
    th.join()
    assert seen == [[10.0 + k] * 2 for k in range(5)]
    assert th.ident not in written
    wp.launch(set_to, 2, inputs=[42.0, out], device="cpu", backend="cpu")  # the owner again
    assert out.numpy().tolist() == [42.0, 42.0] and written[-1] == threading.get_ident()


@pytest.mark.parametrize("where", DEVICES)
def test_a_bad_scalar_on_the_patched_path_is_a_located_error(where):
    out = wp.zeros(1, dtype=float, device=where[0])
    for k in range(3):
        _launch(set_to, 1, [float(k), out], where)
    with pytest.raises(wp.KdslLaunchError, match=r"argument 0 't'") as info:
        _launch(set_to, 1, ["fast", out], where)
    assert info.value.loc is not None and info.value.loc.file == __file__
    vout = wp.zeros(1, dtype=wp.vec3, device=where[0])
    for k in range(3):
        _launch(put_vec, 1, [wp.vec3(k, 0.0, 0.0), vout], where)
    with pytest.raises(wp.KdslLaunchError, match=r"argument 0 'v'"):
        _launch(put_vec, 1, [(1.0, 2.0), vout], where)
    _launch(set_to, 1, [7.5, out], where)  # nothing was half-written
    _launch(put_vec, 1, [wp.vec3(1.0, 2.0, 3.0), vout], where)
    assert out.numpy().tolist() == [7.5] and vout.numpy()[0].tolist() == [1.0, 2.0, 3.0]


@wp.kernel
def narrow(k: wp.int8, out: wp.array(dtype=int)):
    out[0] = int(k)


@pytest.mark.parametrize("where", DEVICES)
def test_an_out_of_range_integer_on_the_patched_path_is_refused(where):
    out = wp.zeros(1, dtype=int, device=where[0])
    for k in range(3):
        _launch(narrow, 1, [k - 1, out], where)
    assert out.numpy().tolist() == [1]
    with pytest.raises(wp.KdslLaunchError, match=r"argument 0 'k'"):
        _launch(narrow, 1, [300, out], where)
    _launch(narrow, 1, [-128, out], where)
    assert out.numpy().tolist() == [-128]


# --- the packers' writers, byte for byte against a fresh pack (no GPU needed) --------

_TYPES = [
    T.ArrayType(T.F32, 1), T.I8, T.F16, T.VectorType(3, T.F32), T.BOOL, T.ArrayType(T.F32, 2),
    T.MatrixType(2, 2, T.F64), T.U64, T.F64, T.I16, T.VectorType(2, T.I32),
]  # fmt: skip
_BY_VALUE = [1, 2, 3, 4, 6, 7, 8, 9, 10]


def _values(k):
    return [
        np.int8(-k), np.float16(0.5 + k), np.array([k, 1.5, -k], np.float32), bool(k % 2),
        np.array([[k, 2.0], [3.0, -k]]), np.uint64(2**63 + k), np.float64(k / 3),
        np.int16(-k * 100), np.array([k, -k], np.int32),
    ]  # fmt: skip


def _args(k, arrays):
    vals = _values(k)
    out = [arrays[0], *vals[:4], arrays[1], *vals[4:]]
    return out


def _fake_cupy(ptr, shape, itemsize=4):
    strides = tuple(int(np.prod(shape[i + 1 :])) * itemsize for i in range(len(shape)))
    data = SimpleNamespace(device_id=0, ptr=ptr)
    return SimpleNamespace(data=data, shape=shape, strides=strides, size=int(np.prod(shape)))


def test_cuda_packer_writer_matches_a_fresh_pack():
    names = [f"a{i}" for i in range(len(_TYPES))]
    packer = Packer(_TYPES, names, debug=False)
    arrays = [_fake_cupy(0x1000, (7,)), _fake_cupy(0x2000, (3, 5))]
    grid = (7, 7, 1, 1, 1)
    buf, _ = packer.pack(_args(0, arrays), 0, grid)
    write = packer.writer(_BY_VALUE)
    for k in (1, 2, 5):
        write(buf, _values(k))
        fresh, _ = packer.pack(_args(k, arrays), 0, grid)
        assert buf.raw == fresh.raw, f"step {k}"
    with pytest.raises(TypeError, match="not a by-value parameter"):
        packer.writer([0])


def test_cuda_packer_writer_refuses_a_value_it_cannot_hold():
    packer = Packer([T.I8, T.ArrayType(T.F32, 1)], ["k", "x"], debug=False)
    buf, _ = packer.pack([np.int8(1), _fake_cupy(0x1000, (2,))], 0, (2, 2, 1, 1, 1))
    with pytest.raises(wp.KdslLaunchError, match="cannot pass the launch arguments"):
        packer.writer([0])(buf, [1000])


def _fake_numpy(shape):
    return np.zeros(shape, np.float32)


def test_cpu_packer_writer_matches_a_fresh_pack():
    packer = ArgPacker(_TYPES)
    arrays = [_fake_numpy((7,)), _fake_numpy((3, 5))]
    buf = packer.new_buffer()
    packer.pack_into(buf, _args(0, arrays))
    write = packer.writer(_BY_VALUE)
    for k in (1, 2, 5):
        write(buf, _values(k))
        fresh = packer.new_buffer()
        packer.pack_into(fresh, _args(k, arrays))
        # The pointer tables differ (each buffer points into itself); the values must not.
        assert buf.raw[packer.start :] == fresh.raw[packer.start :], f"step {k}"
    with pytest.raises(TypeError, match="not a by-value parameter"):
        packer.writer([5])
    with pytest.raises(wp.KdslLaunchError, match="cannot pass the launch arguments"):
        packer.writer([1])(buf, [1000])


@pytest.mark.parametrize("where", DEVICES)
def test_a_recorded_launch_takes_new_scalars_in_place(where):
    dev, backend = where
    x = wp.array(np.arange(4, dtype=np.float32), dtype=float, device=dev)
    y = wp.zeros(4, dtype=float, device=dev)
    cmd = wp.launch(scaled, 4, inputs=[1.0, x, y], device=dev, backend=backend, record_cmd=True)
    cmd.launch()
    run = cmd._run
    for k in range(5):
        t = 0.5 + k
        cmd.set_param_by_name("t", t)
        cmd.launch()
        np.testing.assert_allclose(y.numpy(), np.arange(4) * t * t, rtol=1e-6)
    if _prepares(where):  # written in place: the same packed launch
        assert cmd._run is run
    y2 = wp.zeros(4, dtype=float, device=dev)  # an array: packed afresh
    cmd.set_param_at_index(2, y2)
    cmd.launch()
    np.testing.assert_allclose(y2.numpy(), np.arange(4) * 4.5**2, rtol=1e-6)
    assert cmd._run is not run
    with pytest.raises(wp.KdslLaunchError, match=r"argument 0 't'"):
        cmd.set_param_at_index(0, "slow")
    cmd.set_params([2.0, x, y2])
    cmd.launch()
    np.testing.assert_allclose(y2.numpy(), np.arange(4) * 4.0, rtol=1e-6)


@pytest.mark.parametrize("where", DEVICES)
def test_from_an_exact_entry_to_the_patchable_launch_and_back(where):
    """A scalar changed after an exact entry's launch finds the arrays' patchable launch
    (``relaunch``), and a recurring value finds its exact entry again (the general path:
    the object-key table is emptied before each launch, as after an eviction)."""
    dev = where[0]
    a, b = wp.zeros(2, dtype=float, device=dev), wp.zeros(2, dtype=float, device=dev)
    steps = [(a, 1.0), (a, 1.0), (a, 2.0), (b, 5.0), (a, 1.0), (a, 7.0), (a, 8.0), (a, 1.0)]
    reuse = _reuse(set_first, where)
    kinds = []
    for k, (arr, t) in enumerate(steps):
        reuse.known.clear()
        _launch(set_first, 2, [t, arr], where)
        assert arr.numpy().tolist()[0] == t, f"step {k}"
        kinds.append(None if reuse.same is None else type(reuse.same[4]).__name__)
    if _prepares(where):  # step 4 ran the exact entry of step 1, step 5 the patch
        assert kinds[4] == "tuple" and kinds[5] == "_Patch" and kinds[7] == "_Patch"


@wp.struct
class Gain:
    k: float
    data: wp.array(dtype=float)


@wp.kernel
def gained(g: Gain, t: float, out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = g.k * g.data[i] + t


@pytest.mark.parametrize("where", DEVICES)
def test_struct_parameters_with_changing_scalars(where):
    """A struct parameter keeps plain launches off the reuse tables (its fields may be
    reassigned in place); a recorded launch still takes a new scalar."""
    dev = where[0]
    g = Gain()
    g.k = 2.0
    g.data = wp.array(np.arange(3, dtype=np.float32), device=dev)
    out = wp.zeros(3, dtype=float, device=dev)
    for k in range(4):
        g.k = float(k)  # in place: seen by every plain launch
        _launch(gained, 3, [g, 0.5 * k, out], where)
        np.testing.assert_allclose(out.numpy(), k * np.arange(3) + 0.5 * k)
    assert not _reuse(gained, where).patches
    cmd = wp.launch(gained, 3, inputs=[g, 0.0, out], device=dev, backend=where[1], record_cmd=True)
    for k in range(3):
        cmd.set_param_by_name("t", 10.0 + k)
        cmd.launch()
        np.testing.assert_allclose(out.numpy(), 3 * np.arange(3) + 10.0 + k)


def test_every_kind_compiles_for_cuda_without_a_gpu():
    """The cuda variants above need a GPU; NVRTC alone checks their kernel compiles."""
    pytest.importorskip("cupy_backends.cuda.libs.nvrtc")
    from kdsl.backends.cuda import BACKEND
    from kdsl.compiler import lower

    for kernel in (every_kind, advance, pull, put_vec, narrow, gained):
        assert ".entry" in lower(BACKEND, kernel.build_module(), "ptx", {"arch": "sm_90"})
