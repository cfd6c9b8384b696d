"""``kdsl.Bvh``: every query kind against a float64 brute force, per constructor and leaf
size, on interp and cpu (cuda on the GPU machine); groups, refit, rebuild, empty BVHs,
adversarial boxes, and the tree invariants the stackless traversal relies on."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslTypeError
from kdsl.geometry.bvh import BvhError
from tests.geometry.queries import UNBOUNDED, collect, launch_hits

BACKENDS = ["interp", "cpu"]
CONSTRUCTORS = ["lbvh", "median", "sah"]
cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")


@wp.kernel
def aabb_hits(
    bvh: wp.uint64, lo: wp.array(dtype=wp.vec3), hi: wp.array(dtype=wp.vec3), root: int,
    hits: wp.array2d(dtype=int), counts: wp.array(dtype=int),
):  # fmt: skip
    i = wp.tid()
    collect(wp.bvh_query_aabb(bvh, lo[i], hi[i], root), UNBOUNDED, i, hits, counts)


@wp.kernel
def ray_hits(
    bvh: wp.uint64, start: wp.array(dtype=wp.vec3), dir: wp.array(dtype=wp.vec3),
    max_t: float, hits: wp.array2d(dtype=int), counts: wp.array(dtype=int),
):  # fmt: skip
    i = wp.tid()
    collect(wp.bvh_query_ray(bvh, start[i], dir[i]), max_t, i, hits, counts)


@wp.kernel
def sphere_hits(
    bvh: wp.uint64, centre: wp.array(dtype=wp.vec3), radius: float,
    hits: wp.array2d(dtype=int), counts: wp.array(dtype=int),
):  # fmt: skip
    i = wp.tid()
    collect(wp.bvh_query_sphere(bvh, centre[i], radius), UNBOUNDED, i, hits, counts)


@wp.kernel
def capsule_hits(
    bvh: wp.uint64, start: wp.array(dtype=wp.vec3), dir: wp.array(dtype=wp.vec3),
    radius: float, max_t: float, hits: wp.array2d(dtype=int), counts: wp.array(dtype=int),
):  # fmt: skip
    i = wp.tid()
    collect(wp.bvh_query_capsule(bvh, start[i], dir[i], radius), max_t, i, hits, counts)


@wp.kernel
def group_roots(bvh: wp.uint64, groups: wp.array(dtype=int), roots: wp.array(dtype=int)):
    i = wp.tid()
    roots[i] = wp.bvh_get_group_root(bvh, groups[i])


def hit_sets(lists: list[list[int]]) -> list[set[int]]:
    """Each query's items as a set (no item reported twice)."""
    out = [set(hits) for hits in lists]
    assert [len(s) for s in out] == [len(h) for h in lists], "an item was reported twice"
    return out


def run_query(kernel, n: int, args: list, backend: str, device: str = "cpu"):
    return hit_sets(launch_hits(wp, kernel, n, args, device=device, backend=backend))


# Float64 brute force.
def brute_aabb(lo, hi, qlo, qhi) -> set[int]:
    return set(np.flatnonzero(np.all((lo <= qhi) & (hi >= qlo), axis=1)).tolist())


def ray_box(lo, hi, start, d, max_t, closed=False) -> np.ndarray:
    """Slab test (entry t below max_t, or at it when ``closed``); an axis with a zero direction component holds the whole ray when the
    start lies within the box on that axis (faces included), else none of it."""
    lo, hi, start, d = (np.asarray(a, np.float64) for a in (lo, hi, start, d))
    parallel = d == 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.where(parallel, 1.0, 1.0 / d)
        t0 = (lo - start) * inv
        t1 = (hi - start) * inv
    tmin = np.where(parallel, -np.inf, np.minimum(t0, t1)).max(axis=1)
    tmax = np.where(parallel, np.inf, np.maximum(t0, t1)).min(axis=1)
    inside = np.all(~parallel | ((lo <= start) & (start <= hi)), axis=1)
    near = (tmin <= max_t) if closed else (tmin < max_t)
    return inside & (tmin <= tmax) & (tmax >= 0.0) & near


def brute_ray(lo, hi, start, d, max_t, closed=False) -> set[int]:
    return set(np.flatnonzero(ray_box(lo, hi, start, d, max_t, closed)).tolist())


def brute_sphere(lo, hi, c, r) -> set[int]:
    gap = np.maximum(np.maximum(lo - c, c - hi), 0.0)
    return set(np.flatnonzero((gap**2).sum(axis=1) <= r * r).tolist())


def random_boxes(n: int, seed: int, size: float = 0.05):
    rng = np.random.default_rng(seed)
    c = rng.random((n, 3))
    h = rng.random((n, 3)) * size
    return (c - h).astype(np.float32), (c + h).astype(np.float32)


def make_bvh(lo, hi, constructor, leaf_size=1, groups=None, device="cpu"):
    g = None if groups is None else wp.array(groups, dtype=wp.int32, device=device)
    return wp.Bvh(
        wp.array(lo, dtype=wp.vec3, device=device), wp.array(hi, dtype=wp.vec3, device=device),
        constructor=constructor, groups=g, leaf_size=leaf_size,
    )  # fmt: skip


def check_tree(bvh: wp.Bvh, n: int, leaf_size: int) -> None:
    """The layout's invariants: items a permutation, leaves within leaf_size, every inner
    node's subtree the two children's, bounds that contain the items."""
    t = bvh._tree
    skip, first, count = t.skip.numpy(), t.first.numpy(), t.count.numpy()
    assert sorted(t.items.numpy().tolist()) == list(range(n))
    assert count.max(initial=0) <= leaf_size
    lo, hi = bvh._bounds[0].numpy(), bvh._bounds[1].numpy()
    ilo, ihi = bvh.lowers.numpy(), bvh.uppers.numpy()
    items = t.items.numpy()
    for node in range(t.num_nodes):
        if first[node] >= 0:
            its = items[first[node] : first[node] + count[node]]
            assert count[node] >= 1 and skip[node] == node + 1
            np.testing.assert_array_equal(lo[node], ilo[its].min(axis=0))
            np.testing.assert_array_equal(hi[node], ihi[its].max(axis=0))
        else:
            a = node + 1
            b = skip[a]
            assert b < skip[node] and skip[b] == skip[node]
            np.testing.assert_array_equal(lo[node], np.minimum(lo[a], lo[b]))
            np.testing.assert_array_equal(hi[node], np.maximum(hi[a], hi[b]))
    height = t.height.numpy()[0] if t.height is not None else 0  # (None: an empty tree)
    assert height == tree_height(skip, first, t.num_nodes)


def tree_height(skip, first, num_nodes: int) -> int:
    """The most levels below the root (the depth of the deepest node), from the
    preorder links."""
    ends, deepest = [], 0
    for n in range(num_nodes):
        while ends and ends[-1] <= n:
            ends.pop()
        deepest = max(deepest, len(ends))
        if first[n] < 0:
            ends.append(skip[n])
    return deepest


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("constructor", CONSTRUCTORS)
@pytest.mark.parametrize("leaf_size", [1, 4])
def test_queries_match_brute_force(backend, constructor, leaf_size):
    n, m = (120, 24) if backend == "interp" else (400, 64)
    lo, hi = random_boxes(n, seed=leaf_size)
    bvh = make_bvh(lo, hi, constructor, leaf_size)
    check_tree(bvh, n, leaf_size)
    lo64, hi64 = lo.astype(np.float64), hi.astype(np.float64)
    rng = np.random.default_rng(7)
    qc = rng.random((m, 3)).astype(np.float32)
    qlo, qhi = qc - np.float32(0.04), qc + np.float32(0.04)
    got = run_query(aabb_hits, m, [bvh.id, wp.array(qlo, dtype=wp.vec3),
                                   wp.array(qhi, dtype=wp.vec3), -1], backend)  # fmt: skip
    assert got == [brute_aabb(lo64, hi64, qlo[i], qhi[i]) for i in range(m)]
    start = (rng.random((m, 3)) * 1.4 - 0.2).astype(np.float32)
    d = rng.normal(size=(m, 3)).astype(np.float32)
    got = run_query(ray_hits, m, [bvh.id, wp.array(start, dtype=wp.vec3),
                                  wp.array(d, dtype=wp.vec3), 0.3], backend)  # fmt: skip
    assert got == [brute_ray(lo64, hi64, start[i], d[i], 0.3) for i in range(m)]
    got = run_query(sphere_hits, m, [bvh.id, wp.array(qc, dtype=wp.vec3), 0.06], backend)
    assert got == [brute_sphere(lo64, hi64, qc[i], 0.06) for i in range(m)]
    got = run_query(capsule_hits, m, [bvh.id, wp.array(start, dtype=wp.vec3),
                                      wp.array(d, dtype=wp.vec3), 0.02, 0.2], backend)  # fmt: skip
    want = [brute_ray(lo64 - 0.02, hi64 + 0.02, start[i], d[i], 0.2, True) for i in range(m)]
    assert got == want


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("constructor", CONSTRUCTORS)
def test_adversarial_boxes(backend, constructor):
    # Points (zero-size boxes), duplicates, boxes touching the query box exactly, a
    # flat slab: closed boxes, so touching counts.
    lo = np.array([[0, 0, 0], [0, 0, 0], [1, 0, 0], [2, 2, 2], [0.5, 0.5, 0.5], [3, 0, 0],
                   [1, 1, 1], [0, 5, 0]], np.float32)  # fmt: skip
    hi = lo.copy()
    hi[6] = [2, 2, 1]  # flat in z
    hi[7] = [4, 6, 1]
    bvh = make_bvh(lo, hi, constructor)
    check_tree(bvh, len(lo), 1)
    q = np.array([[0, 0, 0], [1, 1, 1], [2, 2, 2], [-1, -1, -1]], np.float32)
    qh = np.array([[1, 1, 1], [1, 1, 1], [3, 3, 3], [0, 5, 0]], np.float32)
    got = run_query(aabb_hits, 4, [bvh.id, wp.array(q, dtype=wp.vec3),
                                   wp.array(qh, dtype=wp.vec3), -1], backend)  # fmt: skip
    assert got == [{0, 1, 2, 4, 6}, {6}, {3}, {0, 1, 7}]
    assert got == [brute_aabb(lo, hi, q[i], qh[i]) for i in range(4)]
    # Rays along the x axis (zero y and z direction components), parallel to faces; one
    # starting inside box 6, one in the plane of box 6's top face, one pointing away.
    start = np.array([[-1, 0, 0], [1.5, 1.5, 0.5], [-1, 1, 1], [5, 0, 0]], np.float32)
    d = np.array([[1, 0, 0], [0, 0, 1], [1, 0, 0], [1, 0, 0]], np.float32)
    got = run_query(ray_hits, 4, [bvh.id, wp.array(start, dtype=wp.vec3),
                                  wp.array(d, dtype=wp.vec3), 1.0e30], backend)  # fmt: skip
    assert got == [{0, 1, 2, 5}, {6}, {6}, set()]
    assert got == [brute_ray(lo, hi, start[i], d[i], 1e30) for i in range(4)]
    got = run_query(sphere_hits, 1, [bvh.id, wp.array([[3, 0, 1]], dtype=wp.vec3), 1.0], backend)
    assert got == [{5}]


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("constructor", CONSTRUCTORS)
@pytest.mark.parametrize("leaf_size", [1, 4])
def test_nan_boxes_are_never_reported(backend, constructor, leaf_size):
    lo, hi = random_boxes(40, seed=3)
    lo[5] = np.nan
    hi[9, 1] = np.nan
    bvh = make_bvh(lo, hi, constructor, leaf_size)
    assert sorted(bvh._tree.items.numpy().tolist()) == list(range(40))
    rest = set(range(40)) - {5, 9}
    big = wp.array([[-10, -10, -10]], dtype=wp.vec3)
    got = run_query(aabb_hits, 1, [bvh.id, big, wp.array([[10, 10, 10]], dtype=wp.vec3), -1],
                    backend)  # fmt: skip
    assert got == [rest]
    centre = wp.array([[0.5, 0.5, 0.5]], dtype=wp.vec3)
    assert run_query(sphere_hits, 1, [bvh.id, centre, 10.0], backend) == [rest]
    d = wp.array([[0.3, 0.2, 1.0]], dtype=wp.vec3)
    assert run_query(capsule_hits, 1, [bvh.id, centre, d, 10.0, 1.0], backend) == [rest]
    got = run_query(ray_hits, 1, [bvh.id, wp.array([[0.5, 0.5, -1]], dtype=wp.vec3), d, 1e30],
                    backend)  # fmt: skip
    assert 5 not in got[0] and 9 not in got[0]


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("constructor", CONSTRUCTORS)
@pytest.mark.parametrize("leaf_size", [1, 4])
def test_group_roots_confine_queries(backend, constructor, leaf_size):
    n = 90
    lo, hi = random_boxes(n, seed=11)
    groups = np.random.default_rng(2).integers(0, 5, n).astype(np.int32)
    groups[groups == 3] = 4  # group 3 is empty
    bvh = make_bvh(lo, hi, constructor, leaf_size, groups)
    check_tree(bvh, n, leaf_size)
    roots = wp.zeros(7, dtype=int)
    wp.launch(group_roots, dim=7, inputs=[bvh.id, wp.array([0, 1, 2, 3, 4, -1, 9], dtype=int),
                                          roots], backend=backend)  # fmt: skip
    r = roots.numpy()
    assert r[3] == -1 and r[5] == -1 and r[6] == -1
    everything = [wp.array([[-1, -1, -1]], dtype=wp.vec3), wp.array([[2, 2, 2]], dtype=wp.vec3)]
    for g in (0, 1, 2, 4):
        got = run_query(aabb_hits, 1, [bvh.id, *everything, int(r[g])], backend)
        assert got == [set(np.flatnonzero(groups == g).tolist())]


@pytest.mark.parametrize("constructor", CONSTRUCTORS)
def test_refit_and_rebuild_follow_moved_boxes(constructor):
    n = 300
    lo, hi = random_boxes(n, seed=5)
    bvh = make_bvh(lo, hi, constructor, leaf_size=2)
    rng = np.random.default_rng(9)
    shift = (rng.random((n, 3)) * 0.3).astype(np.float32)
    lo2, hi2 = lo + shift, hi + shift
    bvh.lowers.assign(lo2)
    bvh.uppers.assign(hi2)
    bvh.refit()
    check_tree(bvh, n, 2)
    q = rng.random((32, 3)).astype(np.float32)
    args = [wp.array(q - 0.05, dtype=wp.vec3), wp.array(q + 0.05, dtype=wp.vec3), -1]
    want = [brute_aabb(lo2, hi2, q[i] - np.float32(0.05), q[i] + np.float32(0.05))
            for i in range(32)]  # fmt: skip
    assert run_query(aabb_hits, 32, [bvh.id, *args], "cpu") == want
    for other in CONSTRUCTORS:
        bvh.rebuild(other)
        assert bvh.constructor == other
        check_tree(bvh, n, 2)
        assert run_query(aabb_hits, 32, [bvh.id, *args], "cpu") == want


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("constructor", CONSTRUCTORS)
@pytest.mark.parametrize("n", [0, 1, 2])
def test_tiny_bvhs(backend, constructor, n):
    lo, hi = random_boxes(n, seed=1)
    bvh = make_bvh(lo, hi, constructor)
    bvh.refit()
    every = [wp.array([[-1, -1, -1]], dtype=wp.vec3), wp.array([[2, 2, 2]], dtype=wp.vec3), -1]
    assert run_query(aabb_hits, 1, [bvh.id, *every], backend) == [set(range(n))]
    d = wp.array([[0.1, 0.2, 1.0]], dtype=wp.vec3)
    got = run_query(ray_hits, 1, [bvh.id, wp.array([[0.5, 0.5, -3]], dtype=wp.vec3), d, 1e30],
                    backend)  # fmt: skip
    lo64, hi64 = lo.astype(np.float64), hi.astype(np.float64)
    assert got == [brute_ray(lo64, hi64, np.array([0.5, 0.5, -3]), np.array([0.1, 0.2, 1]), 1e30)]


def test_default_constructor_is_per_device():
    lo, hi = random_boxes(10, seed=1)
    assert make_bvh(lo, hi, None).constructor == wp.geometry.bvh.DEFAULT_CONSTRUCTOR["cpu"]


@cuda
@pytest.mark.parametrize("constructor", CONSTRUCTORS)
@pytest.mark.parametrize("leaf_size", [1, 4])
def test_cuda_matches_cpu(constructor, leaf_size):
    n, m = 3000, 256
    lo, hi = random_boxes(n, seed=4, size=0.01)
    groups = np.random.default_rng(3).integers(0, 4, n).astype(np.int32)
    for g in (None, groups):
        bvh = make_bvh(lo, hi, constructor, leaf_size, g, device="cuda:0")
        qc = np.random.default_rng(5).random((m, 3)).astype(np.float32)
        args = [wp.array(qc - 0.03, dtype=wp.vec3, device="cuda:0"),
                wp.array(qc + 0.03, dtype=wp.vec3, device="cuda:0"), -1]  # fmt: skip
        got = run_query(aabb_hits, m, [bvh.id, *args], "cuda", "cuda:0")
        want = [brute_aabb(lo, hi, qc[i] - np.float32(0.03), qc[i] + np.float32(0.03))
                for i in range(m)]  # fmt: skip
        assert got == want
        bvh.refit()
        assert run_query(aabb_hits, m, [bvh.id, *args], "cuda", "cuda:0") == want


def test_sah_splits_between_clusters():
    # 100 boxes near the origin, 300 near (10, 0, 0): the SAH plane separates the clusters
    # (the median centre would cut the larger one).
    rng = np.random.default_rng(0)
    c = np.concatenate([rng.random((100, 3)), rng.random((300, 3)) + [10, 0, 0]])
    lo, hi = (c - 0.01).astype(np.float32), (c + 0.01).astype(np.float32)
    for constructor, want in (("sah", 100), ("median", 200)):
        t = make_bvh(lo, hi, constructor)._tree
        left_end = t.skip.numpy()[1]  # the root's left subtree: nodes 1 .. left_end - 1
        left_items = (t.first.numpy()[1:left_end] >= 0).sum()  # one item per leaf
        assert left_items in (want, 400 - want), constructor


def test_refit_follows_new_box_arrays():
    lo, hi = random_boxes(50, seed=8)
    bvh = make_bvh(lo, hi, "lbvh")
    bvh.lowers, bvh.uppers = wp.array(lo + 5, dtype=wp.vec3), wp.array(hi + 5, dtype=wp.vec3)
    bvh.refit()  # new arrays of the same count: the record follows them
    every = [wp.array([[4, 4, 4]], dtype=wp.vec3), wp.array([[7, 7, 7]], dtype=wp.vec3), -1]
    assert run_query(aabb_hits, 1, [bvh.id, *every], "cpu") == [set(range(50))]
    bvh.lowers = wp.array(lo[:10], dtype=wp.vec3)
    with pytest.raises(KdslTypeError, match="differ in length"):
        bvh.refit()
    bvh.uppers = wp.array(hi[:10], dtype=wp.vec3)
    with pytest.raises(BvhError, match=r"as many boxes .* call rebuild\(\)"):
        bvh.refit()
    bvh.rebuild()
    check_tree(bvh, 10, 1)


@cuda
@pytest.mark.parametrize("constructor", CONSTRUCTORS)
def test_every_query_kind_and_group_roots_on_cuda(constructor):
    dev = "cuda:0"
    n, m = 400, 64
    lo, hi = random_boxes(n, seed=21)
    groups = np.random.default_rng(22).integers(0, 3, n).astype(np.int32)
    lo64, hi64 = lo.astype(np.float64), hi.astype(np.float64)
    rng = np.random.default_rng(23)
    qc = rng.random((m, 3)).astype(np.float32)
    start = (rng.random((m, 3)) * 1.4 - 0.2).astype(np.float32)
    d = rng.normal(size=(m, 3)).astype(np.float32)

    def v3(a):
        return wp.array(a, dtype=wp.vec3, device=dev)

    for g in (None, groups):
        bvh = make_bvh(lo, hi, constructor, 2, g, device=dev)
        got = run_query(ray_hits, m, [bvh.id, v3(start), v3(d), 0.3], "cuda", dev)
        assert got == [brute_ray(lo64, hi64, start[i], d[i], 0.3) for i in range(m)]
        got = run_query(sphere_hits, m, [bvh.id, v3(qc), 0.06], "cuda", dev)
        assert got == [brute_sphere(lo64, hi64, qc[i], 0.06) for i in range(m)]
        got = run_query(capsule_hits, m, [bvh.id, v3(start), v3(d), 0.02, 0.2], "cuda", dev)
        want = [brute_ray(lo64 - 0.02, hi64 + 0.02, start[i], d[i], 0.2, True) for i in range(m)]
        assert got == want
    roots = wp.zeros(4, dtype=int, device=dev)
    wp.launch(group_roots, dim=4, inputs=[bvh.id, wp.array([0, 1, 2, 3], dtype=int, device=dev),
                                          roots], device=dev)  # fmt: skip
    r = roots.numpy()
    assert r[3] == -1
    for k in range(3):
        args = [bvh.id, v3([[-1, -1, -1]]), v3([[2, 2, 2]]), int(r[k])]
        got = hit_sets(launch_hits(wp, aabb_hits, 1, args, max_hits=n, device=dev, backend="cuda"))
        assert got == [set(np.flatnonzero(groups == k).tolist())]
