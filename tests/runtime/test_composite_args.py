"""Vector and matrix launch arguments: the converter keeps one converted value per
distinct value, so the same ``vec3`` passed every step skips the general conversion;
results must match the general path bit for bit, also when the value changes in place."""

import numpy as np
import pytest

import kdsl as wp
from kdsl.runtime import launch as launch_mod
from kdsl.runtime.launch import launch_plan

cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")
DEVICES = ["cpu", pytest.param("cuda:0", marks=cuda)]


@wp.kernel
def _put(g: wp.vec3, m: wp.mat22, out: wp.array(dtype=wp.vec3), outm: wp.array(dtype=wp.mat22)):
    i = wp.tid()
    out[i] = g * float(i + 1)
    outm[i] = m


def _run(device, g, m):
    out = wp.zeros(2, dtype=wp.vec3, device=device)
    outm = wp.zeros(2, dtype=wp.mat22, device=device)
    wp.launch(_put, 2, [g, m, out, outm], device=device)
    return out.numpy(), outm.numpy()


def _want(g, m):
    g = np.asarray(g, dtype=np.float32)
    return np.stack([g, 2 * g]), np.stack([np.asarray(m, dtype=np.float32)] * 2)


@pytest.mark.parametrize("device", DEVICES)
def test_same_vector_object_changed_in_place(device):
    g = wp.vec3(1.0, -2.0, 3.0)
    m = wp.mat22(1.0, 2.0, 3.0, 4.0)
    for value in ([1.0, -2.0, 3.0], [0.0, -0.0, 5.5], [-0.0, 0.0, 5.5], [1e-38, np.inf, -1.0]):
        g[0], g[1], g[2] = value
        m[1, 1] = value[2]
        got, gotm = _run(device, g, m)
        want, wantm = _want(g, m)
        assert got.tobytes() == want.tobytes()  # signed zeros too
        assert gotm.tobytes() == wantm.tobytes()
    np.testing.assert_array_equal(g, np.float32([1e-38, np.inf, -1.0]))  # never written


@pytest.mark.parametrize("device", DEVICES)
def test_cached_conversion_matches_the_general_path(device):
    """Tuples and lists take the general path; kdsl vectors the cached one: same bits."""
    plan = launch_plan(_put, device, None)
    conv = plan.converters[0]
    for value in ((0.1, 0.2, 0.3), (-0.0, 1.0, np.nan), (3.0, 2.0, 1.0)):
        cached = conv(wp.vec3(*value))
        again = conv(wp.vec3(*value))
        general = conv(tuple(value))
        assert cached is again  # one converted value per distinct value
        assert not cached.flags.writeable
        assert cached.dtype == general.dtype and cached.shape == general.shape
        assert cached.tobytes() == general.tobytes()


def test_cache_is_bounded_and_checks_dtype(monkeypatch):
    monkeypatch.setattr(launch_mod, "MAX_COMPOSITES", 4)
    launch_mod.forget(_put)
    conv = launch_plan(_put, "cpu", None).converters[0]
    for i in range(10):
        assert conv(wp.vec3(float(i), 0.0, 0.0))[0] == i
    # the same class with another dtype or shape (NumPy methods keep the subclass) is
    # refused by the general path, not served from the cache
    bad = wp.vec3(1.0, 2.0, 3.0).view(np.int32)
    with pytest.raises(wp.KdslLaunchError, match="argument 0 'g'"):
        wp.launch(_put, 1, [bad, wp.mat22(), wp.zeros(1, dtype=wp.vec3),
                            wp.zeros(1, dtype=wp.mat22)], device="cpu")  # fmt: skip
    wide = wp.vec3(1.0, 2.0, 3.0).astype(np.float64)
    with pytest.raises(wp.KdslLaunchError, match="argument 0 'g'"):
        wp.launch(_put, 1, [wide, wp.mat22(), wp.zeros(1, dtype=wp.vec3),
                            wp.zeros(1, dtype=wp.mat22)], device="cpu")  # fmt: skip
    launch_mod.forget(_put)
