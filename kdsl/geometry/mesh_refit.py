"""What a ``kdsl.Mesh`` recomputes from its points at construction and at every
``refit()``, as kernels on the mesh's device (no copy of the points to the host): the
faces' boxes (the items of its BVH), the sum of the edge lengths (for Warp's
``average_edge_length``, recomputed by refit as Warp's is; it stays on the device, where
the mesh's record points at it) and the check that every point is finite (the one value
a refit reads back)."""

from __future__ import annotations

from kdsl.frontend.api import atomic_min, isfinite, kernel, length, tid
from kdsl.frontend.api import max as vmax
from kdsl.frontend.api import min as vmin
from kdsl.runtime.array import array
from kdsl.runtime.launch import launch
from kdsl.types import float32, int32, vec3
from kdsl.utils import array_sum


@kernel
def _face_boxes(
    points: array(dtype=vec3), indices: array(dtype=int32), lowers: array(dtype=vec3),
    uppers: array(dtype=vec3), edges: array(dtype=float32),
):  # fmt: skip
    f = tid()
    a = points[indices[f * 3]]
    b = points[indices[f * 3 + 1]]
    c = points[indices[f * 3 + 2]]
    lowers[f] = vmin(vmin(a, b), c)
    uppers[f] = vmax(vmax(a, b), c)
    edges[f] = length(b - a) + length(c - a) + length(c - b)


@kernel
def _first_non_finite(points: array(dtype=vec3), first: array(dtype=int32)):
    i = tid()
    if not isfinite(points[i]):
        atomic_min(first, 0, i)


@kernel
def _first_out_of_range(indices: array(dtype=int32), bound: int32, first: array(dtype=int32)):
    i = tid()
    k = indices[i]
    if k < 0 or k >= bound:
        atomic_min(first, 0, i)


def first_index_out_of_range(indices: array, num_points: int, first: array) -> int:
    """The position of the first index outside ``[0, num_points)``, or -1; ``first`` is
    a one-element int32 scratch array on the indices' device."""
    n = indices.shape[0]
    if n == 0:
        return -1
    first.fill_(n)
    launch(_first_out_of_range, dim=n, inputs=[indices, num_points, first],
           device=indices.device)  # fmt: skip
    i = int(first.numpy()[0])
    return -1 if i == n else i


def first_non_finite(points: array, first: array) -> int:
    """The index of the first point with a NaN or infinite coordinate, or -1; ``first``
    is a one-element int32 scratch array on the points' device."""
    n = points.shape[0]
    if n == 0:
        return -1
    first.fill_(n)
    launch(_first_non_finite, dim=n, inputs=[points, first], device=points.device)
    i = int(first.numpy()[0])
    return -1 if i == n else i


def face_boxes(points: array, indices: array, lowers: array, uppers: array, edges: array,
               edge_sum: array) -> None:  # fmt: skip
    """Write each face's box into ``lowers``/``uppers`` and the sum of its three edge
    lengths into ``edges``, and the sum of all of them into ``edge_sum[0]``, on the
    device (the mean edge length is ``edge_sum[0] / (3 * faces)``)."""
    n = lowers.shape[0]
    if n == 0:
        edge_sum.zero_()
        return
    launch(_face_boxes, dim=n, inputs=[points, indices, lowers, uppers, edges],
           device=points.device)  # fmt: skip
    array_sum(edges, out=edge_sum)
