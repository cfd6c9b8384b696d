"""Scaffolding the BVH and hash-grid query tests share: ``collect``, a kdsl function that
records every item a query reports, and ``launch_hits``, which launches a kdsl or Warp
kernel that records hits that way and reads them back.

A recording kernel ends with ``hits: array2d(dtype=int), counts: array(dtype=int)``:
``hits[i]`` holds the first ``hits.shape[1]`` items thread ``i``'s query reported, in
order, and ``counts[i]`` how many it reported in all (exact beyond the row's width)."""

from __future__ import annotations

from typing import Any

import kdsl as wp

#: Most hits a query records unless a test asks for more.
MAX_HITS = 64
#: ``collect``'s ``max_t`` for ``bvh_query_next(q, k)`` without a bound.
UNBOUNDED = -1.0


@wp.func
def advance(q: wp.inout(wp.BvhQuery), k: wp.inout(int), max_t: float) -> bool:
    """``bvh_query_next(q, k)``, or ``bvh_query_next(q, k, max_t)`` for ``max_t >= 0``."""
    if max_t < 0.0:
        return wp.bvh_query_next(q, k)
    return wp.bvh_query_next(q, k, max_t)


@wp.func
def advance(q: wp.inout(wp.HashGridQuery), k: wp.inout(int), max_t: float) -> bool:  # noqa: F811
    """``hash_grid_query_next(q, k)`` (``max_t`` unused)."""
    return wp.hash_grid_query_next(q, k)


@wp.func
def collect(q: Any, max_t: float, i: int, hits: wp.array2d(dtype=int),
            counts: wp.array(dtype=int)):  # fmt: skip
    """Record the items query ``q`` reports in row ``i`` of ``hits`` and their number in
    ``counts[i]`` (``max_t``: see ``advance``)."""
    k = 0
    n = 0
    while advance(q, k, max_t):
        if n < hits.shape[1]:
            hits[i, n] = k
        n += 1
    counts[i] = n


def launch_hits(m: Any, kernel: Any, n: int, args: list, max_hits: int = MAX_HITS,
                device: str = "cpu", **launch: Any) -> list[list[int]]:  # fmt: skip
    """Launch the recording ``kernel`` of module ``m`` (kdsl or warp) over ``n`` threads
    with ``args`` and the hit arrays; each thread's items, in the order reported."""
    hits = m.zeros((n, max_hits), dtype=int, device=device)
    counts = m.zeros(n, dtype=int, device=device)
    m.launch(kernel, dim=n, inputs=[*args, hits, counts], device=device, **launch)
    h, c = hits.numpy(), counts.numpy()
    assert c.max(initial=0) <= max_hits, "test sizes must keep hits under max_hits"
    return [h[i, : c[i]].tolist() for i in range(n)]
