"""``kdsl.HashGrid``'s builds (``kdsl.geometry.hash_grid_build``: the sort of keys and the
counting sort, each tried on every device): the cell tables and point order against a
NumPy model after every kind of rebuild (moved points, fewer, more than reserved, none,
a new radius), the prepared steps and buffers a same-count rebuild reuses, and the
build and query kernels compiled for CUDA (compile only, no GPU needed)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslTypeError
from kdsl.geometry import graph_steps, hash_grid_build
from kdsl.geometry.hash_grid import HashGridError
from kdsl.stdlib import hash_grid
from tests.geometry.graph_stand_in import counting_capture
from tests.geometry.test_hash_grid import (
    brute_sums,
    bucket,
    cell_coord,
    model_candidates,
    run_candidates,
    run_sum,
    scene,
)

cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")
DEVICES = ["cpu", pytest.param("cuda:0", marks=cuda)]
DIMS = (5, 4, 3)


@pytest.fixture(params=["sort", "sort_kernels", "count"])
def build_kind(request, monkeypatch) -> str:
    """Grids made in the test build by the sort of keys (``SortKeys`` or, a GPU's, the
    kdsl merge sort) or by the counting sort."""
    monkeypatch.setattr(
        hash_grid_build, "counting_sort_on", lambda device: request.param == "count"
    )
    monkeypatch.setattr(
        hash_grid_build, "kernel_sort_on", lambda device: request.param == "sort_kernels"
    )
    return request.param


@wp.kernel
def point_order(grid: wp.uint64, out: wp.array(dtype=int)):
    i = wp.tid()
    out[i] = wp.hash_grid_point_id(grid, i)


def model_tables(p: np.ndarray, radius: float, dims, counting: bool) -> tuple[np.ndarray, ...]:
    """The documented build: points stably sorted by bucket, each bucket's ``[start, end)``
    of that order; an empty one's is ``[0, 0)`` (sort of keys) or ``[p, p)`` at its place
    in the order (counting sort)."""
    b = bucket(cell_coord(p * (np.float32(1) / np.float32(radius))), dims)
    order = np.argsort(b, kind="stable")
    cells = int(np.prod(dims))
    counts = np.bincount(b, minlength=cells)
    ends = np.cumsum(counts)
    starts = ends - counts
    if not counting:
        empty = counts == 0
        starts[empty] = 0
        ends[empty] = 0
    return order, starts, ends


def check_tables(grid, p: np.ndarray, radius: float, device: str) -> None:
    """The grid's tables and point order equal the model's for points ``p``."""
    b = grid._builder
    order, starts, ends = model_tables(p, radius, DIMS, isinstance(b, hash_grid_build.CountBuild))
    np.testing.assert_array_equal(b.cell_starts.numpy(), starts)
    np.testing.assert_array_equal(b.cell_ends.numpy(), ends)
    got = wp.zeros(max(len(p), 1), dtype=int, device=device)
    wp.launch(point_order, dim=len(p), inputs=[grid.id, got], device=device)
    np.testing.assert_array_equal(got.numpy()[: len(p)], order)


def built_grid(seed: int, n: int, device: str):
    """``(rng, points as NumPy, as a kdsl array, grid)``: the grid built once, radius 0.2."""
    rng = np.random.default_rng(seed)
    p = scene(rng, n)
    pts = wp.array(p, dtype=wp.vec3, device=device)
    grid = wp.HashGrid(*DIMS, device=device)
    grid.build(pts, 0.2)
    return rng, p, pts, grid


def move(rng, p: np.ndarray, pts, scale: float) -> np.ndarray:
    """Move the points of ``pts`` (now ``p``) in place by a normal step; the new ``p``."""
    p = (p + rng.normal(0.0, scale, p.shape)).astype(np.float32)
    pts.assign(p)
    return p


@pytest.mark.parametrize("device", DEVICES)
def test_tables_follow_every_rebuild(device, build_kind):
    rng, p, pts, grid = built_grid(7, 300, device)
    check_tables(grid, p, 0.2, device)
    for radius in (0.2, 0.35):  # moved in place; then a new cell width as well
        p = move(rng, p, pts, 0.3)
        grid.build(pts, radius)
        check_tables(grid, p, radius, device)
    fewer = p[:40].copy()  # the other buckets of the last build must be emptied
    grid.build(wp.array(fewer, dtype=wp.vec3, device=device), 0.35)
    check_tables(grid, fewer, 0.35, device)
    grid.reserve(1000)  # the buffers grow and the built grid stays as it is
    check_tables(grid, fewer, 0.35, device)
    more = scene(rng, 700)
    grid.build(wp.array(more, dtype=wp.vec3, device=device), 0.2)
    check_tables(grid, more, 0.2, device)
    got = run_candidates(grid, more[:6], 0.2, "cuda" if device != "cpu" else "cpu", device)
    assert got == model_candidates(more, DIMS, 0.2, more[:6], 0.2)
    grid.build(wp.empty(0, dtype=wp.vec3, device=device), 0.2)
    check_tables(grid, more[:0], 0.2, device)
    assert not grid._builder.cell_starts.numpy().any() and not grid._builder.cell_ends.numpy().any()


@pytest.mark.parametrize("device", DEVICES)
def test_same_count_rebuild_reuses_buffers_and_steps(device, build_kind):
    rng, p, pts, grid = built_grid(8, 400, device)
    grid.build(pts, 0.2)  # the second build prepares the steps of a rebuild after one
    b = grid._builder
    steps, buffers = b.steps, (b.point_ids.ptr, b.cell_starts.ptr)
    backend = "cuda" if device != "cpu" else "cpu"
    for radius in (0.2, 0.3, 0.3):
        p = move(rng, p, pts, 0.1)
        grid.build(pts, radius)
        assert b.steps is steps
        assert (b.point_ids.ptr, b.cell_starts.ptr) == buffers
        np.testing.assert_allclose(run_sum(grid, pts, radius, backend, device),
                                   brute_sums(p, radius), atol=2e-4)  # fmt: skip
    other = wp.array(p, dtype=wp.vec3, device=device)  # another array: new steps, same buffers
    grid.build(other, 0.3)
    assert b.steps is not steps
    assert (b.point_ids.ptr, b.cell_starts.ptr) == buffers


def graph_counting(monkeypatch, counting: bool = True) -> dict[str, int]:
    """Grids (the counting sort's, or the sort's with the kdsl merge sort) that replay
    their steps as a graph, captured by the stand-in (``graph_stand_in``). Returns the
    counts of captures and replays."""
    monkeypatch.setattr(hash_grid_build, "counting_sort_on", lambda device: counting)
    monkeypatch.setattr(hash_grid_build, "kernel_sort_on", lambda device: True)
    monkeypatch.setattr(hash_grid_build, "graphs_on", lambda device: True)
    return counting_capture(monkeypatch)


@pytest.mark.parametrize("counting", [True, False])
def test_steps_replay_as_a_graph_from_their_second_run(monkeypatch, counting):
    counts = graph_counting(monkeypatch, counting)
    rng, p, pts, grid = built_grid(9, 300, "cpu")
    grid.build(pts, 0.2)  # new steps (a build after one): run one by one
    assert counts == {"captures": 0, "replays": 0}
    expected = [(1, 1), (1, 2), (1, 2), (2, 3), (2, 4)]
    for radius, want in zip((0.2, 0.2, 0.3, 0.3, 0.3), expected):
        p = move(rng, p, pts, 0.1)
        grid.build(pts, radius)  # a new radius drops the graph and runs one by one
        check_tables(grid, p, radius, "cpu")
        assert (counts["captures"], counts["replays"]) == want, radius


def test_steps_join_an_open_capture_one_by_one(monkeypatch):
    counts = graph_counting(monkeypatch)
    rng, p, pts, grid = built_grid(10, 200, "cpu")
    # A user's capture open (on another device: the CPU's launches run as usual).
    monkeypatch.setattr(graph_steps.graphs, "ACTIVE", [SimpleNamespace(device=None)])
    for _ in range(3):
        p = move(rng, p, pts, 0.1)
        grid.build(pts, 0.2)
        check_tables(grid, p, 0.2, "cpu")
    assert counts == {"captures": 0, "replays": 0}


def test_a_failed_capture_runs_the_steps_one_by_one_from_then_on(monkeypatch):
    counts = graph_counting(monkeypatch)

    def failing(steps, stream):
        counts["captures"] += 1
        return None

    monkeypatch.setattr(graph_steps, "capture_steps", failing)
    rng, p, pts, grid = built_grid(11, 200, "cpu")
    for _ in range(4):
        p = move(rng, p, pts, 0.1)
        grid.build(pts, 0.2)
        check_tables(grid, p, 0.2, "cpu")
    assert counts == {"captures": 1, "replays": 0}


@cuda
def test_cuda_build_replays_a_cuda_graph():
    rng, p, pts, grid = built_grid(12, 5000, "cuda:0")
    for radius in (0.2, 0.2, 0.2, 0.3, 0.3):
        p = move(rng, p, pts, 0.1)
        grid.build(pts, radius)
        check_tables(grid, p, radius, "cuda:0")
    assert grid._builder.steps.graph.graph is not None
    with wp.ScopedCapture(device="cuda:0") as capture:  # inside a user's capture: joins it
        grid.build(pts, 0.3)
    p = move(rng, p, pts, 0.1)
    wp.capture_launch(capture.graph)
    check_tables(grid, p, 0.3, "cuda:0")


def test_build_and_query_kernels_compile_for_cuda():
    """Compile only: the build's kernels and the seed's query through NVRTC (sm_90)."""
    pytest.importorskip("cupy_backends.cuda.libs.nvrtc")
    from kdsl.backends.cuda import BACKEND
    from kdsl.compiler import lower
    from tests.geometry.test_hash_grid import sum as seed_sum

    b = hash_grid_build
    kernels = (b._bucket_keys, b._bucket_ranges, b._count_points, b._count_scatter,
               b._count_order, b._chunk_sums, b._top_prefix, b._chunk_prefix, seed_sum)  # fmt: skip
    for k in kernels:
        assert ".entry" in lower(BACKEND, k.build_module(), "ptx", {"arch": "sm_90"})


@wp.kernel
def wrap_cells(c: wp.array(dtype=int), dims: wp.array(dtype=int), out: wp.array2d(dtype=int)):
    i, j = wp.tid()
    out[i, j] = hash_grid.hash_grid_cell(c[i], 0, 0, dims[j], 1, 1)


@pytest.mark.parametrize("backend", ["interp", "cpu"])
def test_bucket_wraps_every_int32_cell(backend):
    """A cell's bucket along an axis is its coordinate mod the dim (Python's ``%``), for
    coordinates across int32 and dims up to 2**31 - 1 (the division-free wrap)."""
    big = 2**31 - 1
    dims = np.array([1, 2, 3, 7, 128, 1000003, 2**30 + 1, big - 1, big], np.int64)
    edges = [-(2**31), -(2**31) + 1, -big, -1000004, -129, -128, -127, -3, -1, 0, 1, 127,
             128, 129, 1000003, 2**30, big - 2, big - 1]  # fmt: skip
    rng = np.random.default_rng(9)
    c = np.array(edges + list(rng.integers(-(2**31), 2**31 - 1, 40)), np.int64)
    out = wp.zeros((len(c), len(dims)), dtype=int)
    wp.launch(wrap_cells, dim=out.shape, backend=backend,
              inputs=[wp.array(c, dtype=int), wp.array(dims, dtype=int), out])  # fmt: skip
    np.testing.assert_array_equal(out.numpy(), c[:, None] % dims[None, :])


def test_rebuild_checks_what_it_did_not_check_before(build_kind):
    """A rebuild of the last build's array with its radius skips their checks; any other
    radius or array is checked as on the first build."""
    _, p, pts, grid = built_grid(10, 50, "cpu")
    for radius in (float("nan"), 0.0, True, np.float32(-0.2)):
        with pytest.raises((HashGridError, KdslTypeError), match="radius"):
            grid.build(pts, radius)
    with pytest.raises(KdslTypeError, match=r"1-d kdsl\.array of vec3"):
        grid.build(wp.zeros(50, dtype=wp.vec2), 0.2)
    grid.build(pts, np.float32(0.2))  # another type of the same radius: checked, accepted
    grid.build(pts, 0.2)
    check_tables(grid, p, 0.2, "cpu")


def test_a_build_cut_short_leaves_an_empty_grid(build_kind):
    """An error between a build's steps leaves every bucket empty, and the next build
    over the same buffers is right (the counting sort's counts are zero again)."""
    rng, p, pts, grid = built_grid(11, 200, "cpu")
    grid.build(pts, 0.2)
    steps = grid._builder.steps.steps

    def broken():
        raise RuntimeError("cut short")

    steps.insert(2, broken)  # after the first kernel and the sort or scan
    p = move(rng, p, pts, 0.2)
    with pytest.raises(RuntimeError, match="cut short"):
        grid.build(pts, 0.2)
    b = grid._builder
    assert grid.num_points == 0
    assert not b.cell_starts.numpy().any() and not b.cell_ends.numpy().any()
    assert run_candidates(grid, p[:3], 0.2, "cpu") == [[], [], []]
    grid.build(pts, 0.2)
    check_tables(grid, p, 0.2, "cpu")


@pytest.mark.parametrize("device", DEVICES)
def test_count_scan_matches_cumsum(device):
    """The counting sort's scan (kdsl launches, level by level) against NumPy's cumsum,
    at sizes around its chunk's powers, run twice over its prepared launches."""
    rng = np.random.default_rng(12)
    chunk = hash_grid_build.SCAN_CHUNK
    for m in (1, 2, chunk - 1, chunk, chunk + 1, chunk**2, chunk**2 + 1, chunk**3 + 5):
        values = wp.zeros(m, dtype=wp.int32, device=device)
        out = wp.zeros(m, dtype=wp.int32, device=device)
        scan = hash_grid_build._Scan(values, out)
        for _ in range(2):
            v = rng.integers(0, 9, m).astype(np.int32)
            values.assign(v)
            scan()
            np.testing.assert_array_equal(out.numpy(), np.cumsum(v))
