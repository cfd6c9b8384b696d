"""``kdsl.config.verify_autograd_array_access``: a recorded launch that writes an array an
earlier recorded launch read is reported (Warp's setting, used by Warp's
optim/example_fluid_checkpoint_custom_backward)."""

import warnings

import numpy as np
import pytest

import kdsl as wp
from kdsl.ir.array_access import ParamAccess, array_param_access

BACKENDS = ["interp", "cpu"]
cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")


@wp.func
def _bump(a: wp.array(dtype=float), i: int):
    wp.atomic_add(a, i, 1.0)


@wp.kernel
def _double(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = 2.0 * x[i]


@wp.kernel
def _overwrite(x: wp.array(dtype=float)):
    i = wp.tid()
    x[i] = 1.0


@wp.kernel
def _mixed(m: wp.array2d(dtype=float), c: wp.array(dtype=float), n: int, s: wp.array(dtype=float)):
    i = wp.tid()
    row = m[i]  # read through a view
    s[i] = row[0]
    _bump(c, i)  # an atomic inside a called function: a write only


def test_the_analysis_follows_views_and_calls():
    access = array_param_access(_mixed.build_module(), _mixed.key)
    assert access == [
        ParamAccess(read=True),
        ParamAccess(write=True),
        ParamAccess(),
        ParamAccess(write=True),
    ]


@pytest.fixture
def verify():
    wp.config.verify_autograd_array_access = True
    yield
    wp.config.verify_autograd_array_access = False


def _arrays(device):
    x = wp.array(np.arange(3, dtype=np.float32), requires_grad=True, device=device)
    return x, wp.zeros(3, requires_grad=True, device=device)


def _run(backend, device):
    x, y = _arrays(device)
    tape = wp.Tape()
    with tape:
        wp.launch(_double, 3, [x], [y], device=device, backend=backend)
        with pytest.warns(UserWarning) as rec:
            wp.launch(_overwrite, 3, [x], device=device, backend=backend)
    (w,) = rec
    msg = str(w.message)
    assert "argument x in kernel _overwrite" in msg and "test_verify_array_access.py" in msg
    assert "already been read from in a previous launch" in msg
    tape.backward(grads={y: wp.ones(3, device=device)})
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # backward cleared the marks: no warning now
        with tape:
            wp.launch(_overwrite, 3, [x], device=device, backend=backend)


@pytest.mark.parametrize("backend", BACKENDS)
def test_write_after_read_between_launches_warns(verify, backend):
    _run(backend, "cpu")


@cuda
def test_write_after_read_between_launches_warns_cuda(verify):
    _run("cuda", "cuda:0")


def test_views_copies_and_manual_marks(verify):
    x, y = _arrays("cpu")
    tape = wp.Tape()
    with tape:
        wp.launch(_double, 2, [x[1:]], [y[:2]])  # reading a view marks x itself
        with pytest.warns(UserWarning, match="written to by an array copy"):
            wp.copy(x, y)
    tape.reset()
    assert not x._is_read
    y.mark_read()
    with pytest.warns(UserWarning, match="being written to but has already been read"):
        y.mark_write()
    y.mark_init()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        y.mark_write()


def test_off_by_default():
    assert wp.config.verify_autograd_array_access is False
    x, y = _arrays("cpu")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with wp.Tape():
            wp.launch(_double, 3, [x], [y])
            wp.launch(_overwrite, 3, [x])
    assert not x._is_read
