"""The lbvh build's one-launch reduction of the boxes' centre bounds (``centre_bounds``):
the int32 slots it folds the bounds into, decoded here independently, against NumPy's
``nanmin``/``nanmax`` of the centres, on interp and cpu (cuda on the GPU machine)."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.geometry.lbvh import BOUND_SLOTS, centre_bounds

cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")
TARGETS = [("interp", "cpu"), ("cpu", "cpu"), pytest.param("cuda", "cuda:0", marks=cuda)]


def _decode(p: int, q: int) -> np.float32:
    """A maximum kept in two slots: non-negative floats' bits + 1, or inf's bits + 1 less a
    negative float's magnitude bits; 0.0 when neither slot was written."""
    if p > 0:
        bits = p - 1
    elif q > 0:
        bits = (0x7F800001 - q) | 0x80000000
    else:
        return np.float32(0.0)
    return np.array([bits], dtype=np.uint32).view(np.float32)[0]


def _bounds(lo: np.ndarray, hi: np.ndarray, backend: str, device: str, strided=None):
    slots = wp.zeros(BOUND_SLOTS, dtype=wp.int32, device=device)
    centre_bounds(wp.array(lo, dtype=wp.vec3, device=device),
                  wp.array(hi, dtype=wp.vec3, device=device), slots, backend, strided)  # fmt: skip
    s = slots.numpy().tolist()
    top = np.array([_decode(s[4 * a], s[4 * a + 1]) for a in range(3)], np.float32)
    bottom = -np.array([_decode(s[4 * a + 2], s[4 * a + 3]) for a in range(3)], np.float32)
    return bottom, top


def _boxes(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    c = rng.normal(size=(n, 3)).astype(np.float32) * np.float32(100)
    c[:, 1] = -np.abs(c[:, 1]) - np.float32(5)  # an axis with negative centres only
    c[:, 2] = np.abs(c[:, 2]) + np.float32(3)  # and one with positive centres only
    h = rng.random((n, 3)).astype(np.float32)
    return c - h, c + h


@pytest.mark.parametrize(("backend", "device"), TARGETS)
@pytest.mark.parametrize("n", [1, 2, 63, 64, 65, 1500, 3000])
@pytest.mark.parametrize("strided", [False, True])  # a CPU's chunks, a GPU's strides
def test_bounds_are_numpys(backend, device, n, strided):
    if backend == "interp" and n > 100:
        pytest.skip("interp: the small sizes")
    lo, hi = _boxes(n, seed=n)
    c = np.float32(0.5) * (lo + hi)
    got_lo, got_hi = _bounds(lo, hi, backend, device, strided)
    np.testing.assert_array_equal(got_lo, c.min(axis=0))
    np.testing.assert_array_equal(got_hi, c.max(axis=0))


@pytest.mark.parametrize(("backend", "device"), TARGETS)
def test_nan_centres_are_left_out_and_infinities_kept(backend, device):
    lo, hi = _boxes(70, seed=3)
    lo[5] = np.nan  # a NaN box
    hi[9, 1] = np.nan  # one NaN coordinate
    lo[11, 0] = hi[11, 0] = -np.inf  # an infinite centre
    lo[12, 2] = hi[12, 2] = np.inf
    c = np.float32(0.5) * (lo + hi)
    got_lo, got_hi = _bounds(lo, hi, backend, device)
    np.testing.assert_array_equal(got_lo, np.nanmin(c, axis=0))
    np.testing.assert_array_equal(got_hi, np.nanmax(c, axis=0))
    assert got_lo[0] == -np.inf and got_hi[2] == np.inf


@pytest.mark.parametrize(("backend", "device"), TARGETS)
def test_signed_zeros_and_all_nan(backend, device):
    lo = np.array([[0.0, -0.0, np.nan], [-0.0, 0.0, np.nan]], np.float32)
    got_lo, got_hi = _bounds(lo, lo.copy(), backend, device)
    assert got_lo[:2].tolist() == [0.0, 0.0] and got_hi[:2].tolist() == [0.0, 0.0]
    # (the sign of a zero bound depends on the boxes' order; the Morton codes do not)
    assert got_lo[2] == 0.0 and got_hi[2] == 0.0  # no centre on the axis: zeros


def test_lbvh_build_is_deterministic_and_matches_median_queries():
    """Two lbvh builds of boxes spread over negative and positive coordinates give one
    tree (the reduction's atomics leave no order behind)."""
    lo, hi = _boxes(2000, seed=9)
    trees = []
    for _ in range(2):
        bvh = wp.Bvh(wp.array(lo, dtype=wp.vec3), wp.array(hi, dtype=wp.vec3), constructor="lbvh")
        t = bvh._tree
        trees.append([t.skip.numpy().tolist(), t.items.numpy().tolist(), t.first.numpy().tolist()])
    assert trees[0] == trees[1]


def test_every_build_kernel_compiles_for_cuda():
    """Compile-only (no GPU needed): every kernel of the lbvh build, the tree refit and the
    mesh checks through NVRTC (sm_90)."""
    pytest.importorskip("cupy_backends.cuda.libs.nvrtc")
    from kdsl.backends.cuda import nvrtc
    from kdsl.backends.cuda.lower import generate
    from kdsl.frontend.api import Kernel
    from kdsl.geometry import device_tree, lbvh, mesh_refit
    from kdsl.passes import DEFAULT_PIPELINE, run_pipeline

    kernels = [k for mod in (lbvh, device_tree, mesh_refit) for k in vars(mod).values()
               if isinstance(k, Kernel)]  # fmt: skip
    assert len(kernels) >= 9
    units = []
    for i, k in enumerate(kernels):
        m = k.build_module()
        run_pipeline(m, DEFAULT_PIPELINE)
        units.append(f"namespace kd_unit{i} {{\n{generate(m, [k.key]).text}}}\n")
    nvrtc.compile_source("".join(units), "sm_90")


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda:0", marks=cuda)])
@pytest.mark.parametrize("group_ids", [[0], [7], [0, 40], [3, 3, 25], [1, 0, 2, 2]])
def test_group_roots_when_groups_outnumber_nodes(device, group_ids):
    """The Karras kernel sets every group's root to -1 (more groups than its 2n - 1
    threads: each thread sets several); the groups with boxes get theirs."""
    n = len(group_ids)
    lo = np.arange(3 * n, dtype=np.float32).reshape(n, 3)
    bvh = wp.Bvh(wp.array(lo, dtype=wp.vec3, device=device),
                 wp.array(lo + 1, dtype=wp.vec3, device=device), constructor="lbvh",
                 groups=wp.array(group_ids, dtype=wp.int32, device=device))  # fmt: skip
    roots = bvh._tree.group_roots.numpy()
    assert len(roots) == max(group_ids) + 1
    items, first, count = (bvh._tree.items.numpy(), bvh._tree.first.numpy(),
                           bvh._tree.count.numpy())  # fmt: skip
    for g, root in enumerate(roots):
        if g not in group_ids:
            assert root == -1
            continue
        assert root >= 0
        if first[root] >= 0:  # a leaf root holds exactly the group's boxes
            got = sorted(items[first[root] : first[root] + count[root]].tolist())
            assert got == [i for i, x in enumerate(group_ids) if x == g]
