"""What a ``kdsl.Mesh`` recomputes from its points at construction and at every
``refit()``, as kernels on the mesh's device (no copy of the points to the host): the
faces' boxes (the items of its BVH), the average edge length (Warp's
``average_edge_length``, recomputed by refit as Warp's is) and the check that every
point is finite."""

from __future__ import annotations

from kdsl.frontend.api import atomic_min, isfinite, kernel, length, tid
from kdsl.frontend.api import max as vmax
from kdsl.frontend.api import min as vmin
from kdsl.runtime.alloc import empty, full
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


def first_non_finite(points: array) -> int:
    """The index of the first point with a NaN or infinite coordinate, or -1."""
    n = points.shape[0]
    if n == 0:
        return -1
    first = full(1, n, dtype=int32, device=points.device)
    launch(_first_non_finite, dim=n, inputs=[points, first], device=points.device)
    i = int(first.numpy()[0])
    return -1 if i == n else i


def face_boxes(points: array, indices: array, lowers: array, uppers: array) -> float:
    """Write each face's box into ``lowers``/``uppers``; return the mean edge length
    (0 without faces)."""
    n = lowers.shape[0]
    if n == 0:
        return 0.0
    edges = empty(n, dtype=float32, device=points.device)
    launch(_face_boxes, dim=n, inputs=[points, indices, lowers, uppers, edges],
           device=points.device)  # fmt: skip
    return float(array_sum(edges)) / (3 * n)
