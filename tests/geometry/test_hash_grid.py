"""``kdsl.HashGrid``: the seed's neighbour sum against a float64 brute force, the reported
candidates (in order) against a NumPy model of Warp's cell-visit rule and against
warp-lang itself, ``hash_grid_point_id``, rebuilds, ``reserve`` and bad input."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslTypeError
from kdsl.geometry.hash_grid import HashGridError
from tests.geometry.queries import UNBOUNDED, collect, launch_hits

BACKENDS = ["interp", "cpu"]
#: Most candidates a query records (the count is exact beyond it).
MAX_HITS = 640
cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")


@wp.kernel
def sum(grid: wp.uint64, points: wp.array(dtype=wp.vec3), output: wp.array(dtype=wp.vec3),
        radius: float):  # fmt: skip
    # The seed's kernel, unchanged but for formatting.
    tid = wp.tid()
    p = points[tid]
    query = wp.hash_grid_query(grid, p, radius)
    index = int(0)  # noqa: UP018, RUF046 - the seed's spelling
    sum = wp.vec3()
    while wp.hash_grid_query_next(query, index):
        neighbor = points[index]
        dist = wp.length(p - neighbor)
        if dist < radius:
            sum += neighbor
    output[tid] = sum


@wp.kernel
def candidates(grid: wp.uint64, centre: wp.array(dtype=wp.vec3), max_dist: float,
               hits: wp.array2d(dtype=int), counts: wp.array(dtype=int)):  # fmt: skip
    i = wp.tid()
    collect(wp.hash_grid_query(grid, centre[i], max_dist), UNBOUNDED, i, hits, counts)


@wp.kernel
def point_ids(grid: wp.uint64, out: wp.array(dtype=int)):
    i = wp.tid()
    out[i] = wp.hash_grid_point_id(grid, i - 1)  # from -1: out of range on both ends


def brute_sums(p: np.ndarray, radius: float) -> np.ndarray:
    p64 = p.astype(np.float64)
    near = np.linalg.norm(p64[:, None] - p64[None], axis=2) < radius
    return near @ np.nan_to_num(p64)  # a NaN point is no one's neighbour (not even its own)


def run_sum(grid, pts, radius, backend, device="cpu"):
    out = wp.zeros(pts.shape[0], dtype=wp.vec3, device=device)
    wp.launch(sum, dim=pts.shape[0], inputs=[grid.id, pts, out, radius], backend=backend,
              device=device)  # fmt: skip
    return out.numpy()


def run_candidates(grid, centres, max_dist, backend, device="cpu"):
    args = [grid.id, wp.array(centres, dtype=wp.vec3, device=device), max_dist]
    return launch_hits(wp, candidates, len(centres), args, MAX_HITS, device, backend=backend)


def cell_coord(v: np.ndarray) -> np.ndarray:
    """Warp's ``hash_grid_cell_coord``: floor, clamped to int32 (NaN: 0)."""
    c = np.floor(v.astype(np.float64))
    out = np.where(c >= 2.0**31, 2**31 - 2, np.where(c < -(2.0**31), -(2**31), 0))
    ok = (c >= -(2.0**31)) & (c < 2.0**31)
    return np.where(ok, np.nan_to_num(c), out).astype(np.int64)


def bucket(c: np.ndarray, dims) -> np.ndarray:
    """The bucket of cells ``c`` (..., 3) in a grid of ``dims`` (x fastest, wrapped)."""
    return ((c[..., 2] % dims[2]) * dims[1] + c[..., 1] % dims[1]) * dims[0] + c[..., 0] % dims[0]


def model_candidates(p, dims, radius, centres, max_dist):
    """The documented rule: buckets of the cells ``[c - d, c + d]`` overlaps (at most dim
    per axis), x fastest, each bucket's points in original order."""
    inv = np.float32(1) / np.float32(radius)
    pb = bucket(cell_coord(p * inv), dims)
    d = np.float32(max_dist)
    result = []
    for c in np.asarray(centres, np.float32):
        lo = cell_coord((c - d) * inv)
        hi = cell_coord((c + d) * inv)
        hi = np.where(hi - lo >= np.array(dims), lo + np.array(dims) - 1, hi)
        got = []
        for z in range(lo[2], hi[2] + 1):
            for y in range(lo[1], hi[1] + 1):
                for x in range(lo[0], hi[0] + 1):
                    got += list(np.nonzero(pb == bucket(np.array([x, y, z]), dims))[0])
        result.append(got)
    return result


def scene(rng, n):
    """Points in a unit box, a few far outside it (their cells wrap), some coincident, one
    with a NaN coordinate (cell 0 on that axis) and two beyond int32 cells (clamped)."""
    p = rng.random((n, 3)).astype(np.float32)
    p[: n // 10] = rng.uniform(-3.0, 4.0, (n // 10, 3))
    p[-3:] = p[-4]
    p[n // 10 : n // 10 + 3] = [[np.nan, 0.5, 0.5], [1e30, 0.2, 0.3], [0.4, -1e30, 0.6]]
    return p


@pytest.mark.parametrize("backend", BACKENDS)
def test_seed_sum_matches_brute_force(backend):
    rng = np.random.default_rng(1)
    n = 80 if backend == "interp" else 2000
    p = scene(rng, n)
    pts = wp.array(p, dtype=wp.vec3)
    grid = wp.HashGrid(6, 5, 7)
    for radius in (0.1, 0.23):
        grid.build(pts, radius)
        np.testing.assert_allclose(run_sum(grid, pts, radius, backend), brute_sums(p, radius),
                                   atol=2e-4)  # fmt: skip
    # A query radius larger than the build's: more cells, still every neighbour.
    np.testing.assert_allclose(run_sum(grid, pts, 0.5, backend), brute_sums(p, 0.5), atol=2e-3)


@pytest.mark.parametrize("backend", BACKENDS)
def test_candidates_follow_the_cell_visit_rule(backend):
    rng = np.random.default_rng(2)
    p = scene(rng, 200)
    grid = wp.HashGrid(4, 3, 5)
    grid.build(wp.array(p, dtype=wp.vec3), 0.25)
    centres = np.concatenate([rng.uniform(-1.5, 2.5, (20, 3)), p[:4]]).astype(np.float32)
    for max_dist in (0.25, 0.1, 0.6):  # 0.6 spans whole axes: their buckets are not repeated
        got = run_candidates(grid, centres, max_dist, backend)
        assert got == model_candidates(p, (4, 3, 5), 0.25, centres, max_dist)
    # Candidates are not filtered by distance: a point in a visited cell is reported.
    one = wp.HashGrid(1, 1, 1)
    one.build(wp.array([[0.0, 0.0, 0.0], [50.0, -7.0, 3.0]], dtype=wp.vec3), 1.0)
    assert run_candidates(one, [[0.5, 0.5, 0.5]], 0.1, backend) == [[0, 1]]


def test_candidates_match_warp():
    warp = pytest.importorskip("warp")
    warp.config.quiet = True
    warp.init()

    @warp.kernel
    def warp_candidates(grid: warp.uint64, centre: warp.array(dtype=warp.vec3), max_dist: float,
                        hits: warp.array2d(dtype=int), counts: warp.array(dtype=int)):  # fmt: skip
        i = warp.tid()
        q = warp.hash_grid_query(grid, centre[i], max_dist)
        k = int(0)  # noqa: UP018, RUF046 - Warp needs a dynamic variable
        n = int(0)  # noqa: UP018, RUF046
        while warp.hash_grid_query_next(q, k):
            if n < MAX_HITS:
                hits[i, n] = k
            n += 1
        counts[i] = n

    rng = np.random.default_rng(3)
    p = scene(rng, 600)
    centres = np.concatenate([rng.uniform(-1.5, 2.5, (60, 3)), p[:20]]).astype(np.float32)
    dims, radius = (5, 4, 6), 0.2
    grid = wp.HashGrid(*dims)
    grid.build(wp.array(p, dtype=wp.vec3), radius)
    wgrid = warp.HashGrid(*dims, device="cpu")
    wgrid.build(warp.array(p, dtype=warp.vec3, device="cpu"), radius)
    for max_dist in (radius, 0.05, 0.7):
        args = [wgrid.id, warp.array(centres, dtype=warp.vec3, device="cpu"), max_dist]
        want = launch_hits(warp, warp_candidates, len(centres), args, MAX_HITS)
        assert run_candidates(grid, centres, max_dist, "cpu") == want  # same points, same order


@pytest.mark.parametrize("backend", BACKENDS)
def test_point_id_is_the_sorted_order(backend):
    rng = np.random.default_rng(4)
    p = scene(rng, 150)
    grid = wp.HashGrid(3, 4, 5)
    out = wp.zeros(152, dtype=int)
    wp.launch(point_ids, dim=152, inputs=[grid.id, out], backend=backend)
    assert (out.numpy() == -1).all()  # not built yet
    assert run_candidates(grid, [[0.5, 0.5, 0.5]], 1.0, backend) == [[]]
    grid.build(wp.array(p, dtype=wp.vec3), 0.3)
    wp.launch(point_ids, dim=152, inputs=[grid.id, out], backend=backend)
    buckets = bucket(cell_coord(p * (np.float32(1) / np.float32(0.3))), (3, 4, 5))
    ids = out.numpy()
    assert ids[0] == -1 and ids[-1] == -1
    np.testing.assert_array_equal(ids[1:-1], np.argsort(buckets, kind="stable"))


@pytest.mark.parametrize("backend", BACKENDS)
def test_rebuild_moved_points_and_reserve(backend):
    rng = np.random.default_rng(5)
    n = 60 if backend == "interp" else 200
    p = scene(rng, n)
    pts = wp.array(p, dtype=wp.vec3)
    grid = wp.HashGrid(8, 8, 8)
    grid.reserve(n + 100)
    buffers = grid._builder.point_ids.ptr
    grid.build(pts, 0.15)
    for _ in range(2):  # move the points in place and rebuild: same buffers, new answers
        p = (p + rng.normal(0.0, 0.2, p.shape)).astype(np.float32)
        pts.assign(p)
        grid.build(pts, 0.15)
        np.testing.assert_allclose(run_sum(grid, pts, 0.15, backend), brute_sums(p, 0.15),
                                   atol=2e-4)  # fmt: skip
    assert grid._builder.point_ids.ptr == buffers and grid.num_points == n
    grid.build(wp.array(p[: n // 2], dtype=wp.vec3), 0.15)  # fewer points: still no allocation
    assert grid._builder.point_ids.ptr == buffers
    more = scene(rng, 2 * n)
    grid.build(wp.array(more, dtype=wp.vec3), 0.15)  # more than reserved: the buffers grow
    np.testing.assert_allclose(run_sum(grid, wp.array(more, dtype=wp.vec3), 0.15, backend),
                               brute_sums(more, 0.15), atol=2e-4)  # fmt: skip
    grid.build(wp.empty(0, dtype=wp.vec3), 0.15)
    assert run_candidates(grid, [[0.5, 0.5, 0.5]], 0.15, backend) == [[]]


def test_bad_input():
    with pytest.raises(HashGridError, match="dim_y must be positive"):
        wp.HashGrid(4, 0, 4)
    with pytest.raises(HashGridError, match="too many cells"):
        wp.HashGrid(2048, 2048, 1024)
    with pytest.raises(KdslTypeError, match="dim_x must be an int"):
        wp.HashGrid(2.5, 4, 4)
    grid = wp.HashGrid(4, 4, 4)
    pts = wp.zeros(10, dtype=wp.vec3)
    for radius in (0.0, -1.0, float("nan"), float("inf"), 1e-40):
        with pytest.raises(HashGridError, match="radius"):
            grid.build(pts, radius)
    with pytest.raises(KdslTypeError, match="radius must be a number"):
        grid.build(pts, "0.1")
    with pytest.raises(KdslTypeError, match=r"1-d kdsl\.array of vec3"):
        grid.build(wp.zeros(10, dtype=wp.vec2), 0.1)
    with pytest.raises(KdslTypeError, match=r"1-d kdsl\.array of vec3"):
        grid.build(wp.zeros((2, 5), dtype=wp.vec3), 0.1)
    with pytest.raises(KdslTypeError, match=r"1-d kdsl\.array of vec3"):
        grid.build(np.zeros((10, 3), np.float32), 0.1)
    with pytest.raises(HashGridError, match="reserve num_points"):
        grid.reserve(-1)
    with pytest.raises(KdslTypeError, match="reserve num_points must be an int"):
        grid.reserve(1.5)


@cuda
def test_points_on_another_device():
    grid = wp.HashGrid(4, 4, 4, device="cuda:0")
    with pytest.raises(KdslTypeError, match="points are on"):
        grid.build(wp.zeros(10, dtype=wp.vec3, device="cpu"), 0.1)


@cuda
def test_seed_sum_on_cuda():
    rng = np.random.default_rng(6)
    p = scene(rng, 5000)
    pts = wp.array(p, dtype=wp.vec3, device="cuda:0")
    grid = wp.HashGrid(16, 16, 16, device="cuda:0")
    for _ in range(2):  # the second build reuses the buffers
        grid.build(pts, 0.08)
        got = run_sum(grid, pts, 0.08, "cuda", device="cuda:0")
        np.testing.assert_allclose(got, brute_sums(p, 0.08), atol=2e-4)
    centres = np.concatenate([rng.uniform(-1.5, 2.5, (40, 3)), p[:8]]).astype(np.float32)
    got = run_candidates(grid, centres, 0.08, "cuda", device="cuda:0")
    assert got == model_candidates(p, (16, 16, 16), 0.08, centres, 0.08)
