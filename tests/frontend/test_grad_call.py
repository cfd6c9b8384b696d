"""``kdsl.grad(f)(args)``: Warp's ``wp.grad``, in kernels and from Python (issue 14).

Used by Warp's optim/example_particle_repulsion (``f_i -= wp.grad(potential)(d)``).
"""

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslError, KdslTypeError

BACKENDS = ["interp", "cpu"]
cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")


@wp.func
def _cube(x: float):
    return x * x * x


@wp.func
def _spring(d: wp.vec3):
    return wp.dot(d, d)


@wp.func
def _potential(d: wp.vec3, k: float, n: int):
    # calls another func (inlined before it is reversed) and branches
    e = k * _spring(d) + wp.sin(d[0])
    if n > 1:
        e = e * 2.0
    return e


@wp.kernel
def _grads(x: wp.array(dtype=float), v: wp.array(dtype=wp.vec3), out: wp.array(dtype=float),
           gv: wp.array(dtype=wp.vec3), gk: wp.array(dtype=float), gn: wp.array(dtype=int),
           gatan: wp.array(dtype=wp.vec2)):  # fmt: skip
    i = wp.tid()
    out[i] = wp.grad(_cube)(x[i])
    dv, dk, dn = wp.grad(_potential)(v[i], 2.0, i)
    gv[i] = dv
    gk[i] = dk
    gn[i] = dn
    dy, dx = wp.grad(wp.atan2)(x[i], 2.0)
    gatan[i] = wp.vec2(dy, dx)


def _run(backend, device):
    x0 = np.array([0.5, -1.0, 2.0], np.float32)
    v0 = np.array([[1, 2, 3], [0, 1, 0], [-1, 0.5, 2]], np.float32)
    x = wp.array(x0, device=device)
    v = wp.array(v0, dtype=wp.vec3, device=device)
    out, gk = wp.zeros(3, device=device), wp.zeros(3, device=device)
    gv = wp.zeros(3, dtype=wp.vec3, device=device)
    gn = wp.full(3, 7, dtype=int, device=device)
    gatan = wp.zeros(3, dtype=wp.vec2, device=device)
    wp.launch(_grads, 3, [x, v, out, gv, gk, gn, gatan], device=device, backend=backend)
    np.testing.assert_allclose(out.numpy(), 3 * x0**2, rtol=1e-6)
    scale = np.where(np.arange(3) > 1, 2.0, 1.0)[:, None]
    want_v = 2 * 2.0 * v0
    want_v[:, 0] += np.cos(v0[:, 0])
    np.testing.assert_allclose(gv.numpy(), scale * want_v, rtol=1e-5)
    np.testing.assert_allclose(gk.numpy(), scale[:, 0] * (v0 * v0).sum(1), rtol=1e-6)
    assert gn.numpy().tolist() == [0, 0, 0]  # an integer argument's gradient is zero
    r2 = x0**2 + 4
    np.testing.assert_allclose(gatan.numpy(), np.stack([2 / r2, -x0 / r2], 1), rtol=1e-6)


@pytest.mark.parametrize("backend", BACKENDS)
def test_grad_of_funcs_and_builtins_in_a_kernel(backend):
    _run(backend, "cpu")


@cuda
def test_grad_of_funcs_and_builtins_in_a_kernel_cuda():
    _run("cuda", "cuda:0")


def test_grad_from_python_scope():
    assert wp.grad(_cube)(2.0) == pytest.approx(12.0)
    dv, dk, dn = wp.grad(_potential)(wp.vec3(1.0, 0.0, 0.0), 3.0, 0)
    np.testing.assert_allclose(np.asarray(dv), [6 + np.cos(1.0), 0, 0], rtol=1e-6)
    assert dk == pytest.approx(1.0) and dn == 0
    assert wp.grad(wp.sqrt)(4.0) == pytest.approx(0.25)
    assert wp.grad(_cube) == wp.grad(_cube) and "grad(_cube)" in repr(wp.grad(_cube))


@wp.kernel
def _grad_of_grad(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = wp.grad(_cube)(x[i])


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_kernels_adjoint_differentiates_through_grad(backend):
    # Unlike Warp (a constant in the backward pass): d/dx (3 x^2) = 6 x.
    x0 = np.array([1.0, -2.0, 0.5], np.float32)
    x = wp.array(x0, requires_grad=True)
    y = wp.zeros(3, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(_grad_of_grad, 3, [x, y], backend=backend)
    tape.backward(grads={y: wp.ones(3)})
    np.testing.assert_allclose(x.grad.numpy(), 6 * x0, rtol=1e-6)


def _compile(fn):
    wp.kernel(fn).build_module()


@wp.func
def _nothing(x: float):
    print(x)


@wp.func
def _looped(x: float, n: int):
    s = x
    for _ in range(n):
        s = s * x
    return s


def test_misuse_is_a_located_error():
    def not_a_function(a: wp.array(dtype=float)):
        a[0] = wp.grad(3)(a[0])

    with pytest.raises(KdslTypeError, match=r"grad\(\) takes a @kdsl.func or a kernel builtin"):
        _compile(not_a_function)

    def returns_nothing(a: wp.array(dtype=float)):
        wp.grad(_nothing)(a[0])

    with pytest.raises(KdslTypeError, match="_nothing\\(\\) returns nothing") as e:
        _compile(returns_nothing)
    assert "test_grad_call.py" in str(e.value)

    def dynamic_loop(a: wp.array(dtype=float), n: int):
        a[0] = wp.grad(_looped)(a[0], n)

    with pytest.raises(KdslError, match="reverses such loops only in whole kernels") as e:
        _compile(dynamic_loop)
    assert "s = s * x" in str(e.value) or "for _ in range(n)" in str(e.value)

    def keywords(a: wp.array(dtype=float)):
        a[0] = wp.grad(_cube)(x=a[0])

    with pytest.raises(KdslTypeError, match="keyword"):
        _compile(keywords)
    with pytest.raises(KdslTypeError, match="not int"):
        wp.grad(3)

    def bound_to_a_name(a: wp.array(dtype=float)):
        g = wp.grad(_cube)  # Warp allows this; kdsl variables hold values only
        a[0] = g(a[0])

    with pytest.raises(
        KdslTypeError, match="expected a value here, got the Python object 'grad\\(_cube\\)'"
    ):
        _compile(bound_to_a_name)


@wp.func
def _square(x: float):
    return x * x


@wp.kernel
def _two_gradients(x: wp.array(dtype=float), out: wp.array(dtype=float)):
    out[0] = wp.grad(_square)(x[0])
    out[1] = wp.grad(_cube)(x[0])  # same argument types, another function
    out[2] = wp.grad(_square)(x[0] * 2.0)  # the same gradient function, called again


def test_each_function_gets_its_own_gradient_function_once():
    out = wp.zeros(3)
    wp.launch(_two_gradients, 1, [wp.array([1.5], dtype=float), out], backend="interp")
    np.testing.assert_allclose(out.numpy(), [3.0, 6.75, 6.0])
    grads = [f for f in _two_gradients.build_module().funcs if "grad_" in f.attrs["sym_name"]]
    assert len(grads) == 2
