"""Work on ``cuda:0`` while a program has made another GPU current (``set_device``).

A program may call ``kdsl.set_device("cuda:1")`` (CuPy's ``Device.use()``) and then
work on ``cuda:0`` arrays: every primitive, geometry build and array operation must
still act on the arrays' own device. On four GPUs, before the fix, the sort, scan and
BVH builds here acted on copies CuPy had made on the current device (wrong values,
then illegal addresses). Skipped unless two CUDA devices exist.
"""

import numpy as np
import pytest

import kdsl as wp

two_gpus = pytest.mark.skipif(wp.get_cuda_device_count() < 2, reason="needs two CUDA devices")

N = 4096


@wp.kernel
def _add_index(a: wp.array(dtype=wp.float32)):
    i = wp.tid()
    a[i] = a[i] + wp.float32(i)


@wp.kernel
def _query_boxes(bvh: wp.uint64, lo: wp.array(dtype=wp.vec3), hi: wp.array(dtype=wp.vec3),
                 hits: wp.array(dtype=wp.int32)):  # fmt: skip
    i = wp.tid()
    q = wp.bvh_query_aabb(bvh, lo[i], hi[i])
    n = 0
    j = 0
    while wp.bvh_query_next(q, j):
        n += 1
    hits[i] = n


@wp.struct
class _Maybe:
    values: wp.array(dtype=wp.float32)
    unset: wp.array(dtype=wp.float32)


@wp.kernel
def _sample_and_read(tex: wp.Texture2D, m: _Maybe, out: wp.array(dtype=wp.float32)):
    out[0] = wp.texture_sample(tex, wp.vec2(1.5, 0.5), dtype=float)
    out[1] = m.values[0] + wp.float32(m.unset.shape[0])


@pytest.fixture(autouse=True)
def _another_device_current():
    if wp.get_cuda_device_count() < 2:
        yield
        return
    saved = wp.get_device()
    wp.set_device("cuda:1")
    yield
    wp.set_device(saved)


@two_gpus
def test_sort_scan_sum_and_runs_act_on_the_arrays_device():
    rng = np.random.default_rng(7)
    keys = rng.integers(0, 1 << 30, 2 * N).astype(np.int32)
    keys[N:] = 0
    values = np.arange(2 * N, dtype=np.int32)
    k = wp.array(keys, dtype=wp.int32, device="cuda:0")
    v = wp.array(values, dtype=wp.int32, device="cuda:0")
    wp.utils.radix_sort_pairs(k, v, N)
    order = np.argsort(keys[:N], kind="stable")
    np.testing.assert_array_equal(k.numpy()[:N], keys[:N][order])
    np.testing.assert_array_equal(v.numpy()[:N], values[:N][order])

    x = wp.array(rng.random(N).astype(np.float32), device="cuda:0")
    y = wp.empty(N, dtype=wp.float32, device="cuda:0")
    wp.utils.array_scan(x, y, inclusive=True)
    np.testing.assert_allclose(y.numpy(), np.cumsum(x.numpy()), rtol=1e-4)
    assert wp.utils.array_sum(x) == pytest.approx(float(x.numpy().sum()), rel=1e-4)

    runs_in = wp.array(np.repeat(np.arange(5, dtype=np.int32), 3), device="cuda:0")
    rv = wp.empty(15, dtype=wp.int32, device="cuda:0")
    rl = wp.empty(15, dtype=wp.int32, device="cuda:0")
    assert wp.utils.runlength_encode(runs_in, rv, rl) == 5
    np.testing.assert_array_equal(rl.numpy()[:5], 3)


@two_gpus
def test_arrays_launches_and_a_bvh_on_cuda0():
    a = wp.zeros(N, dtype=wp.float32, device="cuda:0")
    a.fill_(1.0)
    wp.launch(_add_index, dim=N, inputs=[a], device="cuda:0")
    b = wp.clone(a)
    assert b.device == "cuda:0"
    np.testing.assert_array_equal(b.numpy(), 1.0 + np.arange(N, dtype=np.float32))

    rng = np.random.default_rng(3)
    centres = rng.random((N, 3)).astype(np.float32)
    lowers = wp.array(centres - 0.01, dtype=wp.vec3, device="cuda:0")
    uppers = wp.array(centres + 0.01, dtype=wp.vec3, device="cuda:0")
    bvh = wp.Bvh(lowers, uppers, constructor="lbvh")
    hits = wp.zeros(N, dtype=wp.int32, device="cuda:0")
    wp.launch(_query_boxes, dim=N, inputs=[bvh.id, lowers, uppers, hits], device="cuda:0")
    lo, hi = centres - 0.01, centres + 0.01
    want = ((lo[:, None, :] <= hi[None, :, :]) & (hi[:, None, :] >= lo[None, :, :])).all(-1)
    np.testing.assert_array_equal(hits.numpy(), want.sum(1))


@two_gpus
def test_textures_and_unset_struct_arrays_on_cuda0():
    # An unset array field is launched as an empty buffer: made on the launch's device,
    # not labelled with the current one (it was refused as "an ndarray on 'cuda:1'").
    tex = wp.Texture2D(np.array([[0.0, 1.0], [2.0, 3.0]], np.float32),
                       filter_mode=wp.TextureFilterMode.CLOSEST, normalized_coords=False,
                       device="cuda:0")  # fmt: skip
    m = _Maybe()
    m.values = wp.full(1, 5.0, dtype=wp.float32, device="cuda:0")
    out = wp.zeros(2, dtype=wp.float32, device="cuda:0")
    wp.launch(_sample_and_read, dim=1, inputs=[tex, m, out], device="cuda:0")
    np.testing.assert_array_equal(out.numpy(), [1.0, 5.0])
