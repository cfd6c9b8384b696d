"""The per-call fast paths of interop: cached tensor views, descriptors, FFI call arguments.

A tensor handed over again gets the view built for it before, as long as nothing the
view depends on changed; these tests change each of those things (the tensor object,
its data pointer, shape, strides, dtype, the kdsl dtype asked for, its gradient) and
check that kdsl follows.
"""

import gc
import weakref

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslError, KdslLaunchError
from kdsl.interop.tensor_cache import TensorViews
from kdsl.interop.torch import VIEWS
from kdsl.testing.cases.programs import make_programs

torch = pytest.importorskip("torch")

BACKENDS = ["interp", "cpu"]


saxpy = make_programs()["saxpy"]  # y = a * x + y


@wp.kernel
def add_one_f64(x: wp.array(dtype=wp.float64)):
    i = wp.tid()
    x[i] = x[i] + wp.float64(1.0)


def test_same_tensor_gives_the_same_view():
    t = torch.arange(8, dtype=torch.float32)
    before = VIEWS.hits
    a, b = wp.from_torch(t), wp.from_torch(t)
    assert a is not b and a._buf is b._buf  # new arrays, one view
    assert VIEWS.hits == before + 1
    c = wp.from_torch(t, return_ctype=True)
    assert c.buf is a._buf and c.owner is t


def test_entry_dies_with_its_tensor_and_keeps_nothing_alive():
    t = torch.arange(8, dtype=torch.float32)
    wp.from_torch(t)
    key, ref = id(t), weakref.ref(t)
    assert key in VIEWS.entries
    del t
    gc.collect()
    assert ref() is None  # the cache held no strong reference to the tensor
    entry = VIEWS.entries.get(key)
    assert entry is None or entry.ref() is not None  # dropped (or a new tensor's)


def test_a_new_tensor_at_a_reused_id_gets_its_own_view():
    # Tensors are made and freed in turn; CPython reuses ids and torch reuses memory,
    # so some of these share an id or an address with a dead one: the view must follow.
    for k in range(1, 40):
        dtype = (torch.float32, torch.float64, torch.int32)[k % 3]
        t = torch.full((k % 5 + 1, 2), k, dtype=dtype)
        a = wp.from_torch(t)
        assert a.shape == tuple(t.shape) and a.ptr == t.data_ptr()
        assert a.numpy().dtype == t.numpy().dtype and (a.numpy() == k).all()
        del t, a


def test_in_place_changes_to_the_tensor_are_seen():
    t = torch.zeros(6, dtype=torch.float32)
    assert wp.from_torch(t).shape == (6,)
    t.resize_(2, 3)  # same storage, new shape
    a = wp.from_torch(t)
    assert a.shape == (2, 3) and a.strides == (12, 4)
    t.as_strided_((3, 2), (1, 3))  # new strides
    assert wp.from_torch(t).strides == (4, 12)
    t.data = torch.arange(5, dtype=torch.float64)  # new memory and dtype, same object
    a = wp.from_torch(t)
    assert a.dtype is wp.float64 and a.ptr == t.data_ptr() and a.numpy().tolist() == [0, 1, 2, 3, 4]
    other = torch.full((5,), 7.0, dtype=torch.float64)
    t.set_(other)  # re-pointed at another tensor's storage
    assert wp.from_torch(t).ptr == other.data_ptr()


def test_the_dtype_asked_for_is_part_of_the_key():
    t = torch.arange(6, dtype=torch.float32).reshape(2, 3)
    v = wp.from_torch(t, dtype=wp.vec3)
    s = wp.from_torch(t)
    assert v.dtype is wp.vec3 and v.shape == (2,)
    assert s.dtype is wp.float32 and s.shape == (2, 3)
    i = torch.arange(4, dtype=torch.int32)
    assert wp.from_torch(i, dtype=wp.uint32).dtype is wp.uint32
    assert wp.from_torch(i).dtype is wp.int32


def test_bad_input_is_refused_every_time():
    t = torch.zeros(4, 2)
    for _ in range(2):  # a failed view is never cached
        with pytest.raises(KdslError, match="last dim must be 3"):
            wp.from_torch(t, dtype=wp.vec3)
    wp.from_torch(t)
    with pytest.raises(KdslError, match="last dim must be 3"):
        wp.from_torch(t, dtype=wp.vec3)
    with pytest.raises(KdslError, match=r"takes a torch\.Tensor"):
        wp.from_torch(np.zeros(3))


def test_grad_follows_the_tensor_grad():
    t = torch.zeros(4, requires_grad=True)
    a = wp.from_torch(t)
    assert a.requires_grad and a.grad.ptr == t.grad.data_ptr()
    t.grad = None  # a new grad is allocated and shared on the next call
    b = wp.from_torch(t)
    assert b.grad.ptr == t.grad.data_ptr()
    g = torch.ones(4)
    t.grad = g
    c = wp.from_torch(t)
    assert c.grad.ptr == g.data_ptr() and (c.grad.numpy() == 1).all()
    assert not wp.from_torch(t, requires_grad=False).requires_grad
    with pytest.raises(KdslError, match="grad has shape"):
        wp.from_torch(t, grad=torch.zeros(3))


@pytest.mark.parametrize("backend", BACKENDS)
def test_direct_launch_follows_a_repointed_tensor(backend):
    x = torch.ones(8)
    y = torch.zeros(8)
    for _ in range(3):  # the third launch reuses the packed arguments
        wp.launch(saxpy, dim=8, inputs=[x, y, 1.0], device="cpu", backend=backend)
    assert y.tolist() == [3.0] * 8
    y.data = torch.zeros(8)  # new memory behind the same object
    wp.launch(saxpy, dim=8, inputs=[x, y, 2.0], device="cpu", backend=backend)
    assert y.tolist() == [2.0] * 8


@pytest.mark.parametrize("backend", BACKENDS)
def test_direct_launch_checks_a_cached_tensor(backend):
    x = torch.ones(8, dtype=torch.float64)
    wp.launch(add_one_f64, dim=8, inputs=[x], device="cpu", backend=backend)
    with pytest.raises(KdslLaunchError, match="got a torch float64 array; convert it"):
        wp.launch(saxpy, dim=8, inputs=[x, torch.zeros(8), 1.0], device="cpu", backend=backend)
    with pytest.raises(KdslLaunchError, match="bfloat16"):
        wp.launch(saxpy, dim=8, inputs=[torch.zeros(8, dtype=torch.bfloat16), torch.zeros(8), 1.0],
                  device="cpu", backend=backend)  # fmt: skip
    assert x.tolist() == [2.0] * 8


@pytest.mark.parametrize("backend", BACKENDS)
def test_return_ctype_descriptors_launch_and_are_checked(backend):
    x, y = torch.ones(4), torch.zeros(4)
    for _ in range(3):
        xc, yc = wp.from_torch(x, return_ctype=True), wp.from_torch(y, return_ctype=True)
        wp.launch(saxpy, dim=4, inputs=[xc, yc, 2.0], device="cpu", backend=backend)
    assert y.tolist() == [6.0] * 4
    bad = wp.from_torch(torch.zeros(4, dtype=torch.float64), return_ctype=True)
    with pytest.raises(KdslLaunchError, match="expected an array of f32, got an array of f64"):
        wp.launch(saxpy, dim=4, inputs=[bad, yc, 2.0], device="cpu", backend=backend)


def test_to_torch_on_the_cpu_shares_memory_and_maps_types():
    a = wp.array(np.arange(4, dtype=np.float32))
    t = wp.to_torch(a)
    t[0] = 9.0
    assert a.numpy()[0] == 9.0 and t.data_ptr() == a.ptr
    u = wp.to_torch(wp.array(np.arange(3, dtype=np.uint32)))
    assert u.dtype == torch.int32 and u.tolist() == [0, 1, 2]
    v = wp.to_torch(wp.zeros(2, dtype=wp.vec3, requires_grad=True))
    assert v.shape == (2, 3) and v.requires_grad and v.grad.shape == (2, 3)
    r = wp.array(np.arange(3, dtype=np.float32))
    r._buf.flags.writeable = False  # read-only data (from_jax) goes through DLPack
    assert wp.to_torch(r).tolist() == [0.0, 1.0, 2.0]


class _FakeTensor:
    """What ``TensorViews`` reads of a tensor, settable by the test."""

    def __init__(self, ptr: int, shape: tuple, stride: tuple, dtype: str = "f32") -> None:
        self.ptr, self.shape, self.strides, self.dtype = ptr, shape, stride, dtype
        self.device = "cpu"

    def data_ptr(self) -> int:
        return self.ptr

    def stride(self) -> tuple:
        return self.strides


def test_tensor_views_key_on_every_field_and_stay_bounded():
    built = []
    views = TensorViews(lambda t, dtype: built.append(1) or (object(), dtype, "cpu"), max_entries=2)
    t = _FakeTensor(1000, (4,), (1,))
    first = views.view(t)[0]
    assert views.view(t)[0] is first and len(built) == 1
    for field, value in [("ptr", 2000), ("shape", (2, 2)), ("strides", (2,)), ("dtype", "f64"),
                         ("device", "cuda:0")]:  # fmt: skip
        setattr(t, field, value)
        now = views.view(t)[0]
        assert now is not first and views.view(t)[0] is now
        first = now
    assert views.view(t, "vec3")[0] is not first  # another asked dtype
    others = [_FakeTensor(k, (1,), (1,)) for k in range(3)]
    for o in others:
        views.view(o)
    assert len(views.entries) == 2  # bounded: the oldest went first


def test_jax_ffi_calls_reuse_arguments_and_follow_new_data():
    jax = pytest.importorskip("jax")
    jnp = jax.numpy
    from kdsl.jax_experimental.ffi import jax_kernel

    js = jax_kernel(saxpy, in_out_argnames=["y"])  # y is aliased: updated in place
    f = jax.jit(lambda x, y: js(x, y, 2.0)[0])
    y = jnp.ones(16, dtype=jnp.float32)
    for k in range(5):
        x = jnp.full(16, float(k), dtype=jnp.float32)
        assert np.asarray(f(x, y)).tolist() == [2.0 * k + 1.0] * 16
    assert 1 <= len(js._prepared) <= 10  # keyed on buffer addresses, which XLA reuses
    g = jax.jit(jax.vmap(lambda x, y: js(x, y, 3.0)[0]))
    batched = g(jnp.ones((3, 16), jnp.float32), jnp.zeros((3, 16), jnp.float32))
    assert np.asarray(batched).tolist() == [[3.0] * 16] * 3
    short = f(jnp.ones(7, jnp.float32), jnp.ones(7, jnp.float32))  # other dims
    assert np.asarray(short).tolist() == [3.0] * 7


@pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")
def test_cuda_tensor_views_are_cached_and_follow_the_tensor():
    if not torch.cuda.is_available():
        pytest.skip("PyTorch sees no CUDA device")
    x = torch.ones(8, device="cuda:0")
    y = torch.zeros(8, device="cuda:0")
    a, b = wp.from_torch(y), wp.from_torch(y)
    assert a._buf is b._buf and a.ptr == y.data_ptr() and a.device == "cuda:0"
    for _ in range(3):
        xc = wp.from_torch(x, return_ctype=True)
        yc = wp.from_torch(y, return_ctype=True)
        wp.launch(saxpy, dim=8, inputs=[xc, yc, 1.0], device="cuda:0")
    wp.synchronize()
    assert y.tolist() == [3.0] * 8
    y.data = torch.zeros(8, device="cuda:0")  # new memory behind the same object
    wp.launch(saxpy, dim=8, inputs=[wp.from_torch(x), wp.from_torch(y), 2.0], device="cuda:0")
    wp.synchronize()
    assert y.tolist() == [2.0] * 8 and wp.from_torch(y).ptr == y.data_ptr()
    t = wp.to_torch(wp.from_torch(y))
    assert t.data_ptr() == y.data_ptr() and t.device == y.device
