"""The cuda backend on a GPU: conformance, debug mode, n-d launches, strided inputs.

Skipped without a CUDA device. Uses only kdsl's public API and the runtime/backend
contract (CUDA arrays hold CuPy buffers; objects with ``__cuda_array_interface__``
are accepted as array arguments).
"""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslLaunchError, KdslRuntimeError
from kdsl.testing.cases import all_cases
from kdsl.testing.conformance import check_case

pytestmark = pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA GPU")

CASES = all_cases()
DEVICE = "cuda:0"


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_conformance(case):
    from kdsl.backends.cuda import BACKEND

    lacking = [c for c in case.requires if c not in BACKEND.capabilities]
    if lacking:
        pytest.skip(f"the cuda backend lacks {', '.join(lacking)}")
    check_case(case, "cuda", DEVICE)


def _arr(values, dtype=np.float32):
    return wp.array(np.asarray(values, dtype=dtype), device=DEVICE)


@wp.kernel(debug=True)
def read_past(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = x[i + 1] * 2.0


@wp.kernel
def double(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = x[i] * 2.0


def test_debug_oob_raises_and_device_stays_usable():
    x, y = _arr(range(4)), _arr(np.zeros(4))
    with pytest.raises(KdslRuntimeError) as info:
        wp.launch(read_past, dim=4, inputs=[x, y], device=DEVICE, backend="cuda")
    text = str(info.value)
    assert "index [4] is out of bounds for array 'x' of shape (4,) in kernel 'read_past'" in text
    assert "y[i] = x[i + 1] * 2.0" in text and "in thread 3" in text
    # The failing thread returned before the access: no fault, the context still works.
    wp.launch(double, dim=4, inputs=[x, y], device=DEVICE, backend="cuda")
    assert y.numpy().tolist() == [0.0, 2.0, 4.0, 6.0]


@wp.kernel(verify_fp=True)
def make_nan(x: wp.array(dtype=float)):
    i = wp.tid()
    x[i] = wp.sqrt(x[i] - 2.0)


def test_verify_fp_reports_nan():
    with pytest.raises(KdslRuntimeError, match="produced NaN"):
        wp.launch(make_nan, dim=4, inputs=[_arr(range(4))], device=DEVICE, backend="cuda")


@wp.kernel
def fill2(m: wp.array2d(dtype=int)):
    i, j = wp.tid()
    m[i, j] = i * 100 + j


@wp.kernel
def fill3(m: wp.array3d(dtype=int)):
    i, j, k = wp.tid()
    m[i, j, k] = i * 10000 + j * 100 + k


@wp.kernel
def fill4(m: wp.array4d(dtype=int)):
    i, j, k, q = wp.tid()
    m[i, j, k, q] = i * 1000000 + j * 10000 + k * 100 + q


@pytest.mark.parametrize(
    "kernel,shape", [(fill2, (37, 300)), (fill3, (5, 7, 90)), (fill4, (3, 4, 5, 6))]
)
def test_nd_launch(kernel, shape):
    m = wp.array(np.zeros(shape, dtype=np.int32), device=DEVICE)
    wp.launch(kernel, dim=shape, inputs=[m], device=DEVICE, backend="cuda")
    idx = np.indices(shape)
    want = sum(ix * 100 ** (len(shape) - 1 - d) for d, ix in enumerate(idx))
    np.testing.assert_array_equal(m.numpy(), want)


def test_non_contiguous_input():
    cupy = pytest.importorskip("cupy")
    with cupy.cuda.Device(0):
        base = cupy.arange(40, dtype=cupy.float32)
        view = base[::4]  # 10 elements, 16-byte stride
        out = cupy.zeros(10, dtype=cupy.float32)
    wp.launch(double, dim=10, inputs=[view, out], device=DEVICE, backend="cuda")
    wp.synchronize()
    np.testing.assert_array_equal(cupy.asnumpy(out), np.arange(0, 40, 4, dtype=np.float32) * 2)


def test_zero_size_launch_is_a_no_op():
    y = _arr(np.ones(3))
    wp.launch(double, dim=0, inputs=[_arr([]), y], device=DEVICE, backend="cuda")
    assert y.numpy().tolist() == [1.0, 1.0, 1.0]


def test_array_on_other_device_is_refused():
    if wp.get_cuda_device_count() < 2:
        pytest.skip("needs two GPUs")
    x = wp.array(np.ones(4, np.float32), device="cuda:1")
    with pytest.raises(KdslLaunchError):
        wp.launch(double, dim=4, inputs=[x, _arr(np.zeros(4))], device=DEVICE, backend="cuda")


@wp.kernel(fast_math=True)
def fast_div(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = 1.0 / x[i]


def test_fast_math_kernel_runs():
    x, y = _arr([1.0, 2.0, 4.0]), _arr(np.zeros(3))
    wp.launch(fast_div, dim=3, inputs=[x, y], device=DEVICE, backend="cuda")
    np.testing.assert_allclose(y.numpy(), [1.0, 0.5, 0.25], rtol=1e-6)


@wp.kernel
def add_value(a: wp.array(dtype=float), value: float):
    i = wp.tid()
    a[i] = a[i] + value


def test_prepared_launch_reruns_and_sees_new_parameters():
    a = wp.zeros(1000, dtype=float, device=DEVICE)
    cmd = wp.launch(add_value, 1000, [a, 1.0], device=DEVICE, record_cmd=True)
    cmd.launch()
    cmd.launch()
    cmd.set_param_at_index(1, 0.5)
    cmd.set_dim(10)
    cmd.launch()
    want = np.full(1000, 2.0, dtype=np.float32)
    want[:10] += 0.5
    np.testing.assert_array_equal(a.numpy(), want)


def test_launches_on_a_user_stream_are_ordered():
    s = wp.Stream(DEVICE)
    a = wp.zeros(1 << 20, dtype=float, device=DEVICE)
    with wp.ScopedStream(s):
        for _ in range(10):
            wp.launch(add_value, a.shape[0], [a, 1.0], device=DEVICE)
    # The read runs on the device's own stream again, which does not wait for ``s`` (as in
    # Warp, ScopedStream's sync_exit is off by default): wait for ``s`` first.
    wp.synchronize_stream(s)
    np.testing.assert_array_equal(a.numpy(), np.full(a.shape[0], 10.0, dtype=np.float32))


@pytest.mark.skipif(wp.get_cuda_device_count() < 2, reason="needs two CUDA devices")
def test_one_kernel_on_two_gpus_in_one_process():
    arrays = {d: wp.zeros(4096, dtype=float, device=d) for d in ("cuda:0", "cuda:1")}
    for step, (d, a) in enumerate(arrays.items(), start=1):
        for _ in range(step):
            wp.launch(add_value, a.shape[0], [a, 1.5], device=d)
    wp.synchronize()
    np.testing.assert_array_equal(arrays["cuda:0"].numpy(), np.full(4096, 1.5, np.float32))
    np.testing.assert_array_equal(arrays["cuda:1"].numpy(), np.full(4096, 3.0, np.float32))
    with pytest.raises(KdslLaunchError, match="cuda:0"):
        wp.launch(add_value, 4096, [arrays["cuda:0"], 1.0], device="cuda:1")
