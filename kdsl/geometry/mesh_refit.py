"""What a ``kdsl.Mesh`` recomputes from its points at construction and at every
``refit()``, as kernels on the mesh's device (no copy of the points to the host): the
faces' boxes (the items of its BVH), the sum of the edge lengths (for Warp's
``average_edge_length``, recomputed by refit as Warp's is; it stays on the device, where
the mesh's record points at it) and the checks that every index is in range and every
point finite: one kernel does all three, and its two answers are the one read back of a
construction or a refit. The arrays it writes are allocated once per mesh
(``FaceBoxes``), so a refit allocates and fills nothing: one launch, one read back and
one sum."""

from __future__ import annotations

from kdsl.frontend.api import atomic_min, isfinite, kernel, length, tid
from kdsl.frontend.api import max as vmax
from kdsl.frontend.api import min as vmin
from kdsl.runtime.alloc import empty, full, zeros
from kdsl.runtime.array import array
from kdsl.runtime.launch import launch
from kdsl.types import float32, int32, vec3
from kdsl.utils.reduce import SumInto

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


class FaceBoxes:
    """What a mesh's checking kernel writes, allocated once per mesh and rewritten by
    every ``write`` (construction and each refit): ``lowers``/``uppers``, the faces'
    boxes (views of one vec3 block); ``edges``, each face's three edge lengths summed,
    and ``edge_sum``, their sum (views of one float32 block; the mean edge length is
    ``edge_sum[0] / (3 * faces)``); ``none``, an empty vec3 array (a mesh's missing
    velocities); and the check's two counters, which hold "nothing found" between
    calls (a call that finds something resets them), so a call fills nothing."""

    def __init__(self, num_tris: int, device) -> None:
        boxes = empty(2 * num_tris, dtype=vec3, device=device)
        self.lowers, self.uppers, self.none = boxes[:num_tris], boxes[num_tris:], boxes[:0]
        # With no faces the sum stays 0.0: nothing writes it.
        sums = (empty if num_tris else zeros)(num_tris + 1, dtype=float32, device=device)
        self.edges, self.edge_sum = sums[:num_tris], sums[num_tris:]
        self._first_bad = full(2, _NONE, dtype=int32, device=device)
        self._sum = SumInto(self.edges, self.edge_sum) if num_tris else None

    def write(self, points: array, indices: array) -> tuple[int, int]:
        """Check the mesh and write its faces' boxes and edge lengths, in one launch and
        one read back (and, when all is good, the edge sum: one reduction).

        Returns (the position of the first index outside ``[0, points)``, the index of
        the first point with a NaN or infinite coordinate), each -1 when there is none;
        with one, the boxes are not meaningful and ``edge_sum`` is left as it was."""
        num_points, num_tris = points.shape[0], self.lowers.shape[0]
        if max(num_points, num_tris) == 0:
            return -1, -1
        first_bad = self._first_bad
        launch(
            _checked_face_boxes, dim=max(num_points, num_tris), device=points.device,
            inputs=[points, indices, num_points, num_tris, self.lowers, self.uppers,
                    self.edges, first_bad],
        )  # fmt: skip
        bad_index, bad_point = (int(x) for x in first_bad.numpy())  # the one read back
        if bad_index == _NONE and bad_point == _NONE:
            if self._sum is not None:
                self._sum()
            return -1, -1
        first_bad.fill_(_NONE)  # "nothing found" again, for the next call
        return (-1 if bad_index == _NONE else bad_index, -1 if bad_point == _NONE else bad_point)
