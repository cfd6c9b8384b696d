"""Warp's kernel builtins ``view(arr, i...)`` and ``array(ptr=..., shape=..., dtype=...)``."""

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslTypeError

BACKENDS = ["interp", "cpu"]
cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")


@wp.kernel
def _wrap(
    p: wp.uint64, n: int, m: int, out: wp.array(dtype=float), g: wp.array3d(dtype=float),
    pv: wp.uint64, vout: wp.array(dtype=wp.vec3),
):  # fmt: skip
    i = wp.tid()
    a = wp.array(ptr=p, shape=(n, m), dtype=float)
    out[i] = a[i, 0] + a[i, 1] + float(a.shape[1])
    a[i, 2] = 7.0  # stores reach the wrapped memory
    r = wp.view(g, i, 1)  # 1-d
    r[0] = float(i)
    plane = wp.view(g, i)  # 2-d
    plane[0, 1] = 5.0
    v = wp.array(pv, n, wp.vec3)  # positional, one extent
    vout[i] = v[i] * 2.0


def _run(backend, device):
    data = np.arange(12, dtype=np.float32).reshape(4, 3)
    src = wp.array(data, device=device)
    vecs = wp.array(data, dtype=wp.vec3, device=device)
    out = wp.zeros(4, device=device)
    g = wp.zeros((4, 2, 2), device=device)
    vout = wp.zeros(4, dtype=wp.vec3, device=device)
    wp.launch(_wrap, 4, [wp.uint64(src.ptr), 4, 3, out, g, wp.uint64(vecs.ptr), vout],
              device=device, backend=backend)  # fmt: skip
    np.testing.assert_array_equal(out.numpy(), data[:, 0] + data[:, 1] + 3)
    np.testing.assert_array_equal(src.numpy()[:, 2], 7.0)
    np.testing.assert_array_equal(g.numpy()[:, 1, 0], np.arange(4))
    np.testing.assert_array_equal(g.numpy()[:, 0, 1], 5.0)
    np.testing.assert_array_equal(vout.numpy(), 2 * data)


@pytest.mark.parametrize("backend", BACKENDS)
def test_view_and_array_from_a_pointer(backend):
    _run(backend, "cpu")


@cuda
def test_view_and_array_from_a_pointer_cuda():
    _run("cuda", "cuda:0")


def _compile(fn):
    wp.kernel(fn).build_module()


@pytest.mark.parametrize(
    "body, message",
    [
        ("wp.view(a, 0, 0)", "takes fewer than 2 indices, got 2"),
        ("wp.view(a[0, 0], 0)", "view\\(\\) needs an array first, not f32"),
        ("wp.array(ptr=p, shape=(4,))", "missing dtype"),
        ("wp.array(ptr=a[0, 0], shape=4, dtype=float)", "ptr must be a uint64 address, not f32"),
        ("wp.array(ptr=p, shape=(1, 1, 1, 1, 1), dtype=float)", "shape has 1 to 4 dims, not 5"),
        ("wp.array(ptr=p, shape=4, dtype=a)", "dtype must be a kdsl value type"),
        ("wp.array(p, 4, float, dtype=float)", "got an argument twice"),
    ],
)
def test_misuse_is_a_located_error(body, message, tmp_path):
    ns = {"wp": wp}
    src = f"def k(a: wp.array2d(dtype=float), p: wp.uint64):\n    x = {body}\n"
    path = tmp_path / "misuse.py"
    path.write_text(src)
    exec(compile(src, str(path), "exec"), ns)
    with pytest.raises(KdslTypeError, match=message) as e:
        _compile(ns["k"])
    assert "misuse.py" in str(e.value)
