"""``a[i]`` on an n-d array inside a kernel is an (n-1)-d view, as in Warp (issue 14, item 4).

The view (``kd.array_view``) shares the array's memory: it can be indexed, named,
passed to ``@func``s, stored through, updated atomically, and gradients flow through
it into the array's gradient.
"""

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslRuntimeError, KdslSyntaxError, KdslTypeError

BACKENDS = ["interp", "cpu"]
cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")


@wp.func
def _row_sum(r: wp.array(dtype=float)) -> float:
    s = 0.0
    for j in range(r.shape[0]):
        s += r[j]
    return s


@wp.func
def _fill_row(r: wp.array(dtype=float), v: float):
    for j in range(r.shape[0]):
        r[j] = v


@wp.kernel
def _rows(a: wp.array2d(dtype=float), out: wp.array(dtype=float), b: wp.array2d(dtype=float)):
    i = wp.tid()
    r = a[i]
    out[i] = _row_sum(r) + r[0] * r[1]
    br = b[i]
    br[0] = r[2] * 2.0
    b[i][1] = a[i][0]
    wp.atomic_add(b[i], 2, 1.0)
    b[i][3] += r[3]


def _run_rows(backend, device):
    data = np.arange(12, dtype=np.float32).reshape(3, 4)
    a = wp.array(data, requires_grad=True, device=device)
    out = wp.zeros(3, requires_grad=True, device=device)
    b = wp.zeros((3, 4), requires_grad=True, device=device)
    tape = wp.Tape()
    with tape:
        wp.launch(_rows, dim=3, inputs=[a], outputs=[out, b], device=device, backend=backend)
    np.testing.assert_allclose(out.numpy(), data.sum(1) + data[:, 0] * data[:, 1])
    want_b = np.stack([2 * data[:, 2], data[:, 0], np.ones(3), data[:, 3]], axis=1)
    np.testing.assert_allclose(b.numpy(), want_b)
    out.grad.fill_(1.0)
    b.grad.fill_(1.0)
    tape.backward()
    g = np.ones((3, 4), np.float32)  # the row sums
    g[:, 0] += data[:, 1] + 1  # r[0] * r[1], and b[i][1] = a[i][0]
    g[:, 1] += data[:, 0]
    g[:, 2] += 2  # b[i][0] = 2 r[2]
    g[:, 3] += 1  # b[i][3] += r[3]
    np.testing.assert_allclose(a.grad.numpy(), g)


@pytest.mark.parametrize("backend", BACKENDS)
def test_rows_are_views_forward_and_backward(backend):
    _run_rows(backend, "cpu")


@cuda
def test_rows_are_views_forward_and_backward_cuda():
    _run_rows("cuda", "cuda:0")


@wp.kernel
def _slabs(c: wp.array3d(dtype=wp.vec2), out: wp.array3d(dtype=wp.vec2)):
    i, j = wp.tid()
    slab = c[i]  # 2-d
    line = slab[j]  # 1-d
    o = out[i]
    for k in range(line.shape[0]):
        o[j, k] = line[k] * 2.0 + c[i, j][k]
    _fill_row_first(out[i][j], slab.shape[0])


@wp.func
def _fill_row_first(r: wp.array(dtype=wp.vec2), n: int):
    r[0] = wp.vec2(float(n), float(r.shape[0]))


@pytest.mark.parametrize("backend", BACKENDS)
def test_three_d_views_of_vectors(backend):
    data = np.random.default_rng(0).uniform(-1, 1, (2, 3, 4, 2)).astype(np.float32)
    c = wp.array(data, dtype=wp.vec2)
    out = wp.zeros((2, 3, 4), dtype=wp.vec2)
    wp.launch(_slabs, dim=(2, 3), inputs=[c], outputs=[out], backend=backend)
    want = 3 * data
    want[:, :, 0] = [3.0, 4.0]
    np.testing.assert_allclose(out.numpy(), want, rtol=1e-6)


@pytest.mark.parametrize("backend", BACKENDS)
def test_views_of_strided_arrays(backend):
    # A row of a transposed array is a column of the original (strides from the descriptor).
    data = np.arange(12, dtype=np.float32).reshape(3, 4)
    a = wp.array(data)
    out = wp.zeros(4)
    wp.launch(_row_sums, dim=4, inputs=[a.transpose()], outputs=[out], backend=backend)
    np.testing.assert_allclose(out.numpy(), data.sum(0))
    grid = wp.zeros((4, 3))
    wp.launch(_fill_rows, dim=2, inputs=[grid[::2]], backend=backend)
    assert grid.numpy()[:, 0].tolist() == [0.0, 0.0, 1.0, 0.0]


@wp.kernel
def _row_sums(a: wp.array2d(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = _row_sum(a[i])


@wp.kernel
def _fill_rows(a: wp.array2d(dtype=float)):
    i = wp.tid()
    _fill_row(a[i], float(i))


@wp.kernel(debug=True)
def _bad_row(a: wp.array2d(dtype=float), k: int):
    i = wp.tid()
    r = a[k]
    r[i] = 1.0


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_row_out_of_range_is_caught(backend):
    a = wp.zeros((2, 3))
    with pytest.raises(KdslRuntimeError, match="out of bounds"):
        wp.launch(_bad_row, dim=3, inputs=[a, 5], backend=backend)


def test_view_errors_point_at_the_code():
    @wp.kernel
    def store_row(a: wp.array2d(dtype=float)):
        i = wp.tid()
        a[i] = 1.0

    @wp.kernel
    def rebind(a: wp.array2d(dtype=float), b: wp.array2d(dtype=float)):
        i = wp.tid()
        r = a[i]
        r = b[i]

    @wp.kernel
    def too_many(a: wp.array2d(dtype=float)):
        i = wp.tid()
        a[i][0][1] = 1.0

    with pytest.raises(KdslTypeError, match="2-d array needs 2 indices"):
        wp.launch(store_row, dim=1, inputs=[wp.zeros((1, 1))], backend="interp")
    with pytest.raises(KdslSyntaxError, match="cannot assign to the array 'r'"):
        wp.launch(rebind, dim=1, inputs=[wp.zeros((1, 1)), wp.zeros((1, 1))], backend="interp")
    with pytest.raises(KdslTypeError, match=r"cannot be indexed|cannot assign"):
        wp.launch(too_many, dim=1, inputs=[wp.zeros((1, 2))], backend="interp")
