"""``kdsl.optim``: Adam and SGD against a NumPy reference and against Warp 1.19, step by step.

Each optimizer runs N steps with fresh random gradients on interp, cpu and cuda, over
scalar, vector and matrix dtypes; the parameters and buffers after every step are
compared with a float64 NumPy transcription of Warp's formulas (float16 rounded as the
kernels round it) and, where warp-lang is installed, with ``warp.optim`` run on the same
inputs.
"""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
import kdsl.optim
from kdsl.optim import SGD, Adam, OptimError, OptimShapeError, OptimTypeError
from tests.device_targets import TARGETS

DTYPES = [wp.float32, wp.float64, wp.float16, wp.vec3, wp.vec2d, wp.mat22, wp.vec3h]
RTOL = {np.float16: 2e-3, np.float32: 2e-5, np.float64: 1e-12}
STEPS = 4
N = 6


def _np_scalar(dtype) -> type:
    return np.dtype(wp.dtype_to_numpy(dtype)).type


def _random(dtype, rng, shape=(N,)) -> np.ndarray:
    inner = tuple(np.asarray(dtype()).shape) if not issubclass(dtype, wp.types.Scalar) else ()
    return rng.uniform(-1.0, 1.0, size=shape + inner).astype(_np_scalar(dtype))


def _close(got, want, dtype) -> None:
    rtol = RTOL[_np_scalar(dtype)]
    np.testing.assert_allclose(np.asarray(got, np.float64), want, rtol=rtol, atol=rtol)


class AdamRef:
    """Warp's Adam, transcribed in NumPy (float16 computed in float32 and rounded)."""

    def __init__(self, p, lr, betas, eps):
        self.p, self.lr, (self.b1, self.b2), self.eps = p.copy(), lr, betas, eps
        self.work = np.float32 if p.dtype == np.float16 else p.dtype.type
        self.m = np.zeros(p.shape, self.work)
        self.v = np.zeros(p.shape, self.work)
        self.t = 0

    def step(self, g):
        w, g = self.work, g.astype(self.work)
        b1, b2, lr, eps, t = w(self.b1), w(self.b2), w(self.lr), w(self.eps), w(self.t)
        self.m = b1 * self.m + (w(1) - b1) * g
        self.v = b2 * self.v + (w(1) - b2) * g * g
        mhat = self.m / (w(1) - b1 ** (t + w(1)))
        vhat = self.v / (w(1) - b2 ** (t + w(1)))
        self.p = self.p - (lr * mhat / (np.sqrt(vhat) + eps)).astype(self.p.dtype)
        self.t += 1


class SGDRef:
    """Warp's SGD, transcribed in NumPy."""

    def __init__(self, p, lr, momentum, dampening, weight_decay, nesterov):
        self.p, self.lr, self.mu, self.damp = p.copy(), lr, momentum, dampening
        self.wd, self.nesterov = weight_decay, nesterov
        self.work = np.float32 if p.dtype == np.float16 else p.dtype.type
        self.b = np.zeros_like(p)
        self.t = 0

    def step(self, g):
        w = self.work
        gt = g.astype(w)
        if self.wd != 0.0:
            gt = gt + w(self.wd) * self.p.astype(w)
        if self.mu != 0.0:
            bt = gt if self.t == 0 else w(self.mu) * self.b.astype(w) + (w(1) - w(self.damp)) * gt
            gt = gt + w(self.mu) * bt if self.nesterov else bt
            self.b = bt.astype(self.p.dtype)
        self.p = (self.p.astype(w) - w(self.lr) * gt).astype(self.p.dtype)
        self.t += 1


@pytest.mark.parametrize("device, backend", TARGETS)
@pytest.mark.parametrize("dtype", DTYPES, ids=lambda d: d.__name__)
def test_adam_matches_numpy_step_by_step(device, backend, dtype):
    rng = np.random.default_rng(1)
    p0 = _random(dtype, rng)
    params = wp.array(p0, dtype=dtype, device=device)
    opt = Adam([params], lr=0.05, betas=(0.8, 0.99), eps=1e-6, backend=backend)
    ref = AdamRef(p0, 0.05, (0.8, 0.99), 1e-6)
    assert opt.m[0].dtype == (dtype if dtype not in (wp.float16, wp.vec3h) else
                              {wp.float16: wp.float32, wp.vec3h: wp.vec3f}[dtype])  # fmt: skip
    for _ in range(STEPS):
        g = _random(dtype, rng)
        opt.step([wp.array(g, dtype=dtype, device=device)])
        ref.step(g)
        _close(params.numpy(), ref.p, dtype)
        _close(opt.m[0].numpy(), ref.m, dtype)
        _close(opt.v[0].numpy(), ref.v, dtype)
    assert opt.t == STEPS


SGD_SETTINGS = [
    dict(),
    dict(momentum=0.9),
    dict(momentum=0.9, dampening=0.3, weight_decay=0.1),
    dict(momentum=0.8, nesterov=True, weight_decay=0.05),
    dict(weight_decay=0.2),
]


@pytest.mark.parametrize("device, backend", TARGETS)
@pytest.mark.parametrize("dtype", DTYPES, ids=lambda d: d.__name__)
@pytest.mark.parametrize("settings", SGD_SETTINGS, ids=lambda s: ",".join(s) or "plain")
def test_sgd_matches_numpy_step_by_step(device, backend, dtype, settings):
    rng = np.random.default_rng(2)
    p0 = _random(dtype, rng)
    params = wp.array(p0, dtype=dtype, device=device)
    opt = SGD([params], lr=0.1, backend=backend, **settings)
    full = dict(momentum=0.0, dampening=0.0, weight_decay=0.0, nesterov=False) | settings
    ref = SGDRef(p0, 0.1, **full)
    for _ in range(STEPS):
        g = _random(dtype, rng)
        opt.step([wp.array(g, dtype=dtype, device=device)])
        ref.step(g)
        _close(params.numpy(), ref.p, dtype)
        _close(opt.b[0].numpy(), ref.b, dtype)


@pytest.mark.parametrize("device, backend", TARGETS)
def test_several_parameter_arrays_of_mixed_dtypes_and_ranks(device, backend):
    """One optimizer, a list of arrays: a 2-d array is updated in place through its flat
    view, and each array keeps its own buffers."""
    rng = np.random.default_rng(3)
    a0, b0 = _random(wp.float32, rng, (3, 4)), _random(wp.vec3, rng, (5,))
    a = wp.array(a0, dtype=wp.float32, device=device)
    b = wp.array(b0, dtype=wp.vec3, device=device)
    opt = Adam([a, b], lr=0.1, backend=backend)
    refs = [AdamRef(a0, 0.1, (0.9, 0.999), 1e-8), AdamRef(b0, 0.1, (0.9, 0.999), 1e-8)]
    for _ in range(3):
        ga, gb = _random(wp.float32, rng, (3, 4)), _random(wp.vec3, rng, (5,))
        opt.step([wp.array(ga, device=device), wp.array(gb, dtype=wp.vec3, device=device)])
        refs[0].step(ga)
        refs[1].step(gb)
    assert opt.m[0].shape == (3, 4) and opt.m[1].dtype == wp.vec3
    _close(a.numpy(), refs[0].p, wp.float32)
    _close(b.numpy(), refs[1].p, wp.vec3)


@pytest.mark.parametrize("device, backend", TARGETS)
def test_flattened_views_update_the_original_as_warps_examples_do(device, backend):
    x = wp.array(np.full((2, 3), 2.0, np.float32), device=device, requires_grad=True)
    x.grad.fill_(1.0)
    opt = SGD([x.flatten()], lr=0.5, backend=backend)
    opt.step([x.grad.flatten()])
    np.testing.assert_array_equal(x.numpy(), np.full((2, 3), 1.5, np.float32))


def test_a_changed_learning_rate_applies_to_the_next_step():
    p = wp.zeros(2, dtype=float)
    g = wp.ones(2, dtype=float)
    opt = SGD([p], lr=1.0)
    opt.step([g])
    opt.lr = 0.25
    opt.step([g])
    np.testing.assert_array_equal(p.numpy(), [-1.25, -1.25])


@pytest.mark.parametrize("cls, kwargs", [(Adam, {"lr": 0.1}), (SGD, {"lr": 0.1, "momentum": 0.9})])
def test_reset_internal_state_restarts_the_optimizer(cls, kwargs):
    rng = np.random.default_rng(4)
    p0, grads = _random(wp.float32, rng), [_random(wp.float32, rng) for _ in range(3)]
    p, q = wp.array(p0), wp.array(p0)
    first, fresh = cls([p], **kwargs), cls([q], **kwargs)
    for g in grads:
        first.step([wp.array(g)])
    first.reset_internal_state()
    assert first.t == 0
    for buf in first.m + first.v if cls is Adam else first.b:
        assert not buf.numpy().any()
    p.assign(p0) if hasattr(p, "assign") else wp.copy(p, wp.array(p0))
    for g in grads:
        first.step([wp.array(g)])
        fresh.step([wp.array(g)])
    np.testing.assert_array_equal(p.numpy(), q.numpy())


def test_set_params_keeps_fitting_buffers_and_reallocates_the_rest():
    p = wp.zeros(4, dtype=float)
    opt = Adam(lr=0.1)
    assert opt.params is None and opt.m == []
    opt.set_params([p])
    m = opt.m[0]
    opt.step([wp.ones(4, dtype=float)])
    opt.set_params([wp.zeros(4, dtype=float)])
    assert opt.m[0] is m  # same shape and dtype: the moments carry over, as in Warp
    opt.set_params([wp.zeros(3, dtype=wp.vec3)])
    assert opt.m[0].shape == (3,) and opt.m[0].dtype == wp.vec3 and not opt.m[0].numpy().any()
    opt.set_params([])
    opt.step([])  # nothing to update; the step still counts
    assert opt.t == 2


def test_step_detail_is_warps_static_update():
    p, g = wp.full(3, 1.0, dtype=float), wp.full(3, 2.0, dtype=float)
    m, v = wp.zeros(3, dtype=float), wp.zeros(3, dtype=float)
    Adam.step_detail(g, m, v, 0.1, 0.9, 0.999, 0, 1e-8, p)
    np.testing.assert_allclose(p.numpy(), 0.9, rtol=1e-6)
    b = wp.zeros(3, dtype=float)
    SGD.step_detail(g, b, 0.5, 0.0, 0.0, 0.0, False, 0, p)
    np.testing.assert_allclose(p.numpy(), -0.1, rtol=1e-6)


def test_the_package_is_warps_module_path():
    assert wp.optim is kdsl.optim
    assert {"Adam", "SGD"} <= set(kdsl.optim.__all__)


# --- bad input ----------------------------------------------------------------------------


def test_step_before_params_is_an_error():
    for opt in (Adam(), SGD()):
        with pytest.raises(OptimError, match="parameters must be set before calling step"):
            opt.step([])


@pytest.mark.parametrize("cls", [Adam, SGD])
def test_bad_gradients_are_refused_with_warps_exception_types(cls):
    p = wp.zeros(4, dtype=float)
    opt = cls([p])
    with pytest.raises(
        OptimTypeError, match="dtype must match parameter dtype float32, got float64"
    ):
        opt.step([wp.zeros(4, dtype=wp.float64)])
    with pytest.raises(TypeError):
        opt.step([wp.zeros(4, dtype=wp.vec3)])
    with pytest.raises(
        OptimShapeError, match=r"shape must match parameter shape \(4,\), got \(5,\)"
    ):
        opt.step([wp.zeros(5, dtype=float)])
    with pytest.raises(ValueError):
        opt.step([wp.zeros((2, 2), dtype=float)])
    with pytest.raises(OptimError, match="got 2 grad arrays for 1 parameter arrays"):
        opt.step([wp.zeros(4, dtype=float)] * 2)
    with pytest.raises(OptimError, match="gradient must be a kdsl array, got ndarray"):
        opt.step([np.zeros(4, np.float32)])
    with pytest.raises(OptimError, match="grad must be a list of kdsl arrays"):
        opt.step(wp.zeros(4, dtype=float))
    assert opt.t == 0 and not p.numpy().any()


@pytest.mark.parametrize("cls", [Adam, SGD])
def test_bad_parameters_are_refused(cls):
    with pytest.raises(OptimError, match=r"params\[1\] has dtype int32; supported are float16"):
        cls([wp.zeros(2, dtype=float), wp.zeros(2, dtype=int)])
    with pytest.raises(OptimError, match=r"params\[0\] must be a kdsl array, got list"):
        cls([[1.0, 2.0]])
    with pytest.raises(OptimError, match="params must be a list of kdsl arrays, got array"):
        cls(wp.zeros(2, dtype=float))
    with pytest.raises(OptimError, match=r"params\[0\] must be contiguous or one-dimensional"):
        cls([wp.zeros((4, 4), dtype=float)[:, 1:3]])
    with pytest.raises(OptimError, match=r"params\[0\] has dtype transformf"):
        cls([wp.zeros(2, dtype=wp.transform)])
    with pytest.raises(OptimError, match="lr must be a real number, got 'fast'"):
        cls([wp.zeros(2, dtype=float)], lr="fast")


@pytest.mark.parametrize("device, backend", TARGETS)
def test_sgd_updates_quaternions_component_wise_as_warps_does(device, backend):
    rng = np.random.default_rng(3)
    p0 = _random(wp.quat, rng)
    params = wp.array(p0, dtype=wp.quat, device=device)
    opt = SGD([params], lr=0.1, momentum=0.5, weight_decay=0.1, backend=backend)
    ref = SGDRef(p0, 0.1, momentum=0.5, dampening=0.0, weight_decay=0.1, nesterov=False)
    for _ in range(2):
        g = _random(wp.quat, rng)
        opt.step([wp.array(g, dtype=wp.quat, device=device)])
        ref.step(g)
        _close(params.numpy(), ref.p, wp.quat)


def test_adam_refuses_quaternions_as_warps_does():
    with pytest.raises(
        OptimError, match=r"params\[0\] has dtype quatf; supported are .* vectors and"
    ):
        Adam([wp.zeros(2, dtype=wp.quat)])


def test_bad_adam_hyperparameters_and_buffers_are_refused():
    with pytest.raises(OptimError, match=r"betas must be a pair \(beta1, beta2\), got 0.9"):
        Adam(betas=0.9)
    with pytest.raises(OptimError, match="beta2 must be a real number, got None"):
        Adam(betas=(0.9, None))
    p, g = wp.zeros(3, dtype=wp.float16), wp.zeros(3, dtype=wp.float16)
    with pytest.raises(OptimTypeError, match="first moment m dtype must be float32, got float16"):
        Adam.step_detail(g, wp.zeros(3, dtype=wp.float16), wp.zeros(3, dtype=float), 0.1, 0.9,
                         0.99, 0, 1e-8, p)  # fmt: skip
    with pytest.raises(OptimShapeError, match="second moment v must have the parameter's shape"):
        Adam.step_detail(g, wp.zeros(3, dtype=float), wp.zeros(2, dtype=float), 0.1, 0.9,
                         0.99, 0, 1e-8, p)  # fmt: skip
    opt = Adam([wp.zeros(2, dtype=float)])
    opt.lr = None
    with pytest.raises(OptimError, match="lr must be a real number, got None"):
        opt.step([wp.zeros(2, dtype=float)])


@pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")
def test_a_gradient_on_another_device_is_refused():
    opt = SGD([wp.zeros(2, dtype=float, device="cuda:0")])
    with pytest.raises(OptimError, match="gradient is on device 'cpu', the parameter on 'cuda:0'"):
        opt.step([wp.zeros(2, dtype=float, device="cpu")])


# --- against Warp 1.19 -------------------------------------------------------------------


def _warp():
    pytest.importorskip("warp")
    import warp
    import warp.optim

    warp.config.quiet = True
    return warp


@pytest.mark.parametrize("device, backend", TARGETS)
@pytest.mark.parametrize("dtype", ["float32", "vec3", "float16"])
def test_adam_matches_warp_step_by_step(device, backend, dtype):
    warp = _warp()
    kd, wd = getattr(wp, dtype), getattr(warp, dtype)
    rng = np.random.default_rng(5)
    p0 = _random(kd, rng)
    ours = wp.array(p0, dtype=kd, device=device)
    theirs = warp.array(p0, dtype=wd, device=device)
    a = Adam([ours], lr=0.03, betas=(0.85, 0.995), eps=1e-7, backend=backend)
    b = warp.optim.Adam([theirs], lr=0.03, betas=(0.85, 0.995), eps=1e-7)
    for _ in range(STEPS):
        g = _random(kd, rng)
        a.step([wp.array(g, dtype=kd, device=device)])
        b.step([warp.array(g, dtype=wd, device=device)])
        _close(ours.numpy(), theirs.numpy().astype(np.float64), kd)
        _close(a.v[0].numpy(), b.v[0].numpy().astype(np.float64), kd)
    assert a.t == b.t


@pytest.mark.parametrize("device, backend", TARGETS)
@pytest.mark.parametrize("dtype", ["float32", "vec3", "mat22"])
@pytest.mark.parametrize("settings", SGD_SETTINGS, ids=lambda s: ",".join(s) or "plain")
def test_sgd_matches_warp_step_by_step(device, backend, dtype, settings):
    """(Warp's SGD kernel does not compile for float64 arrays: it multiplies them by
    float32 scalars; kdsl's takes float64 hyperparameters there.)"""
    warp = _warp()
    kd, wd = getattr(wp, dtype), getattr(warp, dtype)
    rng = np.random.default_rng(6)
    p0 = _random(kd, rng)
    ours = wp.array(p0, dtype=kd, device=device)
    theirs = warp.array(p0, dtype=wd, device=device)
    a = SGD([ours], lr=0.2, backend=backend, **settings)
    b = warp.optim.SGD([theirs], lr=0.2, **settings)
    for _ in range(STEPS):
        g = _random(kd, rng)
        a.step([wp.array(g, dtype=kd, device=device)])
        b.step([warp.array(g, dtype=wd, device=device)])
        _close(ours.numpy(), theirs.numpy().astype(np.float64), kd)
        _close(a.b[0].numpy(), b.b[0].numpy().astype(np.float64), kd)
