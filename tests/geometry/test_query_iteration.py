"""``for index in query:`` over geometry queries (Warp's iteration form), on every host backend."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp

BACKENDS = ["interp", "cpu"]
RNG = np.random.default_rng(3)
CENTERS = RNG.random((60, 3)).astype(np.float32)


@wp.kernel
def boxes_touching(bvh: wp.uint64, lo: wp.array(dtype=wp.vec3), hi: wp.array(dtype=wp.vec3),
                   out: wp.array(dtype=int)):  # fmt: skip
    i = wp.tid()
    query = wp.bvh_query_aabb(bvh, lo[i], hi[i])
    n = 0
    for item in query:
        if item != i:
            n += 1
    out[i] = n


@wp.kernel
def neighbours_within(grid: wp.uint64, pts: wp.array(dtype=wp.vec3), r: float,
                      out: wp.array(dtype=int)):  # fmt: skip
    i = wp.tid()
    neighbors = wp.hash_grid_query(grid, pts[i], r)
    n = 0
    for _rep in range(2):  # an outer loop around the query loop carries both right
        neighbors = wp.hash_grid_query(grid, pts[i], r)
        for index in neighbors:
            if wp.length(pts[index] - pts[i]) <= r:
                n += 1
    out[i] = n


@pytest.mark.parametrize("backend", BACKENDS)
def test_for_over_a_bvh_query(backend):
    lo = wp.array(CENTERS - 0.08, dtype=wp.vec3)
    hi = wp.array(CENTERS + 0.08, dtype=wp.vec3)
    bvh = wp.Bvh(lo, hi)
    out = wp.zeros(len(CENTERS), dtype=int)
    wp.launch(boxes_touching, dim=len(CENTERS), inputs=[bvh.id, lo, hi, out], backend=backend)
    a, b = CENTERS - 0.08, CENTERS + 0.08
    overlap = np.all(a[:, None] <= b[None], axis=2) & np.all(b[:, None] >= a[None], axis=2)
    np.testing.assert_array_equal(out.numpy(), overlap.sum(1) - 1)


@pytest.mark.parametrize("backend", BACKENDS)
def test_for_over_a_hash_grid_query_inside_another_loop(backend):
    pts = wp.array(CENTERS, dtype=wp.vec3)
    grid = wp.HashGrid(4, 4, 4)
    grid.build(pts, 0.2)
    out = wp.zeros(len(CENTERS), dtype=int)
    wp.launch(neighbours_within, dim=len(CENTERS), inputs=[grid.id, pts, 0.2, out],
              backend=backend)  # fmt: skip
    d = np.linalg.norm(CENTERS[:, None].astype(np.float64) - CENTERS[None], axis=2)
    np.testing.assert_array_equal(out.numpy(), 2 * (d <= 0.2).sum(1))


def test_for_over_a_value_that_is_not_a_query_is_still_refused():
    @wp.kernel
    def not_a_query(x: wp.array(dtype=float)):
        v = wp.vec3(1.0, 2.0, 3.0)
        for c in v:
            x[0] = c

    with pytest.raises(wp.KdslSyntaxError, match="must iterate over range"):
        wp.launch(not_a_query, dim=1, inputs=[wp.zeros(1)])
