"""What a ``kdsl.Mesh`` recomputes from its points at construction and at every
``refit()``, as kernels on the mesh's device (no copy of the points to the host): the
faces' boxes (the items of its BVH), the sum of the edge lengths (for Warp's
``average_edge_length``, recomputed by refit as Warp's is; it stays on the device, where
the mesh's record points at it) and the checks that every index is in range and every
point finite: one kernel does all three, and its two answers are the one read back of a
construction or a refit."""

from __future__ import annotations

from kdsl.frontend.api import atomic_min, isfinite, kernel, length, tid
from kdsl.frontend.api import max as vmax
from kdsl.frontend.api import min as vmin
from kdsl.runtime.array import array
from kdsl.runtime.launch import launch
from kdsl.types import float32, int32, vec3
from kdsl.utils import array_sum

#: What the check's two counters start at: above every position (a 1-d array of int32).
_NONE = 2**31 - 1


@kernel
def _checked_face_boxes(
    points: array(dtype=vec3), indices: array(dtype=int32), num_points: int32,
    num_tris: int32, lowers: array(dtype=vec3), uppers: array(dtype=vec3),
    edges: array(dtype=float32), first_bad: array(dtype=int32),
):  # fmt: skip
    # Thread i checks point i (``first_bad[1]``: the first non-finite one) and face i's
    # three indices (``first_bad[0]``: the first position out of range), and writes face
    # i's box and edge lengths (zeros for a face with a bad index: nothing out of range
    # is read).
    i = tid()
    if i < num_points and not isfinite(points[i]):
        atomic_min(first_bad, 1, i)
    if i >= num_tris:
        return
    bad = -1
    for k in range(3):
        v = indices[i * 3 + k]
        if bad < 0 and (v < 0 or v >= num_points):
            bad = i * 3 + k
    if bad >= 0:
        atomic_min(first_bad, 0, bad)
        lowers[i] = vec3()
        uppers[i] = vec3()
        edges[i] = 0.0
        return
    a = points[indices[i * 3]]
    b = points[indices[i * 3 + 1]]
    c = points[indices[i * 3 + 2]]
    lowers[i] = vmin(vmin(a, b), c)
    uppers[i] = vmax(vmax(a, b), c)
    edges[i] = length(b - a) + length(c - a) + length(c - b)


def checked_face_boxes(points: array, indices: array, lowers: array, uppers: array,
                       edges: array, edge_sum: array, first_bad: array) -> tuple[int, int]:  # fmt: skip
    """Check the mesh and write its faces' boxes, in one launch and one read back.

    Writes each face's box into ``lowers``/``uppers`` and the sum of its three edge
    lengths into ``edges``, and, when every value is good, the sum of all of them into
    ``edge_sum[0]`` (the mean edge length is ``edge_sum[0] / (3 * faces)``).
    ``first_bad`` is a two-element int32 scratch array on the mesh's device. Returns
    (the position of the first index outside ``[0, points)``, the index of the first
    point with a NaN or infinite coordinate), each -1 when there is none; with one,
    the boxes are not meaningful and ``edge_sum`` is left as it was."""
    num_points, num_tris = points.shape[0], lowers.shape[0]
    if max(num_points, num_tris) == 0:
        edge_sum.zero_()
        return -1, -1
    first_bad.fill_(_NONE)
    launch(
        _checked_face_boxes, dim=max(num_points, num_tris), device=points.device,
        inputs=[points, indices, num_points, num_tris, lowers, uppers, edges, first_bad],
    )  # fmt: skip
    bad_index, bad_point = (int(x) for x in first_bad.numpy())  # the one read back
    bad = (-1 if bad_index == _NONE else bad_index, -1 if bad_point == _NONE else bad_point)
    if bad == (-1, -1):
        if num_tris:
            array_sum(edges, out=edge_sum)
        else:
            edge_sum.zero_()
    return bad
