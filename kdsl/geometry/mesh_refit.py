"""What a ``kdsl.Mesh`` recomputes from its points at construction and at every
``refit()``, as kernels on the mesh's device (no copy of the points to the host): the
faces' boxes (the items of its BVH), the sum of the edge lengths (for Warp's
``average_edge_length``, recomputed by refit as Warp's is; it stays on the device, where
the mesh's record points at it) and the checks that every index is in range and every
point finite: one kernel does all three, and its two answers are the one read back of a
construction or a refit. The arrays it writes are allocated once per mesh
(``FaceBoxes``), so a refit allocates and fills nothing.

``FaceBoxes.start`` issues the checking kernel, the read back of its answers (into
pinned memory on a side stream, behind an event: ``host_read``) and the edge sum
(``ChunkSum``: kdsl kernels, skipped on the device when the check found something, so
the sum is left as it was); ``finish`` waits for the read only. A construction issues
its BVH build between the two, so the host never waits for the build. A refit hands
``start`` the BVH's refit and the gather of the vertex copy (``MeshBvh.
refit_checked_steps``, ``TreePoints.prepared``: they read the answers on the device and
write nothing when they are set); on a GPU the check comes first, then the BVH's
refit on the stream beside the read back with the sum and the gather on two side
streams (``ForkedSteps``), all one CUDA graph from the second refit, whose replay
records the event the host waits for; then ``finish`` raises (session 12,
docs/performance.md).
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from typing import Any

from kdsl.frontend.api import atomic_max, isfinite, kernel, length, tid
from kdsl.geometry.finite_minmax import high3, low3
from kdsl.geometry.forked_steps import ForkedSteps, side_streams
from kdsl.geometry.graph_steps import graphs_on
from kdsl.geometry.host_read import IntsReader
from kdsl.geometry.mesh_tree_points import TreePoints
from kdsl.geometry.recycle import RecycleBin
from kdsl.runtime.alloc import empty, zeros
from kdsl.runtime.array import array
from kdsl.runtime.carve import carve
from kdsl.runtime.graphs import state as graphs
from kdsl.runtime.launch import launch
from kdsl.runtime.stream import current_stream
from kdsl.types import float32, int32, vec3
from kdsl.utils.chunk_sum import ChunkSum, scratch_size

#: The check's two counters keep the maximum of ``_TOP - position`` of the bad values
#: found: zero (where they start) is "nothing found", larger values earlier positions.
_TOP = 2**31 - 1


@kernel
def _checked_face_boxes(
    points: array(dtype=vec3), indices: array(dtype=int32), num_points: int32,
    num_tris: int32, lowers: array(dtype=vec3), uppers: array(dtype=vec3),
    edges: array(dtype=float32), first_bad: array(dtype=int32),
):  # fmt: skip
    # Thread i checks point i (``first_bad[1]``: the first non-finite one) and face i's
    # three indices (``first_bad[0]``: the first position out of range), each counter
    # keeping the largest ``_TOP - position``, and writes face
    # i's box and edge lengths (zeros for a face with a bad index: nothing out of range
    # is read).
    i = tid()
    if i < num_points and not isfinite(points[i]):
        atomic_max(first_bad, 1, _TOP - i)
    if i >= num_tris:
        return
    bad = -1
    for k in range(3):
        v = indices[i * 3 + k]
        if bad < 0 and (v < 0 or v >= num_points):
            bad = i * 3 + k
    if bad >= 0:
        atomic_max(first_bad, 0, _TOP - bad)
        lowers[i] = vec3()
        uppers[i] = vec3()
        edges[i] = 0.0
        return
    a = points[indices[i * 3]]
    b = points[indices[i * 3 + 1]]
    c = points[indices[i * 3 + 2]]
    lowers[i] = low3(low3(a, b), c)  # (a NaN point is reported: no box is used then)
    uppers[i] = high3(high3(a, b), c)
    edges[i] = length(b - a) + length(c - a) + length(c - b)


class FaceBoxes:
    """What a mesh's checking kernel writes, allocated once per mesh (one zeroed float32
    block, viewed) and rewritten by every ``start`` (construction and each refit):
    ``lowers``/``uppers``, the faces' boxes; ``edges``, each face's three edge lengths
    summed, and ``edge_sum``, their sum (the mean edge length is ``edge_sum[0] / (3 *
    faces)``; 0.0 with no faces); ``none``, an empty vec3 array (a mesh's missing
    velocities); and ``found``, the check's two counters, which hold "nothing found"
    (zero) between calls (a call that finds something zeroes them again), so a call
    fills nothing; kernels issued behind a check may read them (a mesh's BVH refit and
    vertex copy write nothing when they are set). Also ``tree_points``, the mesh's vertex copy in
    tree order (``TreePoints``: ``3 * faces`` vec3, not zeroed, and its prepared
    launches), which comes back with the boxes when they are recycled. The check's launch is prepared per
    points and indices arrays (and stream), the sum's once (and replayed as a graph on a
    GPU from its second run)."""

    def __init__(self, num_tris: int, device) -> None:
        floats = 7 * num_tris + 1  # boxes (six per face), edges, their sum
        m, scratch = num_tris, scratch_size(num_tris)
        # (and the two counters, then the sum's scratch)
        block = zeros(floats + 2 + scratch, dtype=float32, device=device)
        (self.lowers, self.uppers, self.none, self.edges, self.edge_sum, self.found,
         self._scratch) = carve(block, [
            (0, vec3, m), (12 * m, vec3, m), (0, vec3, 0), (24 * m, float32, m),
            (28 * m, float32, 1), (4 * floats, int32, 2), (4 * floats + 8, float32, scratch),
        ])  # fmt: skip
        self.tree_points = TreePoints(empty(3 * num_tris, dtype=vec3, device=device), self.found)
        self._read = IntsReader(self.found)
        #: The edge sum's prepared launches per stream they were prepared on.
        self._sums: dict[Any, list] = {}
        #: The last two runs of the sum and a ``start``'s ``then``/``beside``
        #: (``ForkedSteps``), with what they were made of: (then, beside, stream, run,
        #: check: the check's launch when the run issues it, else None).
        self._tails: list[tuple] = []
        #: (points, indices, stream) of the prepared check, and the check.
        self._check: tuple | None = None
        self._pending = False
        #: Whether the last ``start`` was finished (one cut short may leave a counter set).
        self.clean = True

    def start(self, points: array, indices: array, then: Sequence[Callable[[], object]] = (),
              beside: Sequence[Callable[[], object]] = ()) -> None:  # fmt: skip
        """Issue the check of the mesh, the writes of its faces' boxes and edge lengths,
        the read back of the check's answers and the edge sum, and behind the check the
        prepared launches ``then`` (on the stream) and ``beside`` (prepared on
        ``beside_stream()``): a refit's BVH refit and the copy's gather, which read the
        check's counters on the device. ``finish`` waits for the answers; nothing waits
        here. With a ``then`` or ``beside`` on a GPU, ``then`` runs on the stream beside
        the read back and the sum (one side stream) and ``beside`` (another), and the
        stream waits for all three (``ForkedSteps``): from the second call with the same
        launches the check and all of it are one CUDA graph, whose replay records the
        event the read back's wait is for."""
        num_points, num_tris = points.shape[0], self.lowers.shape[0]
        if max(num_points, num_tris) == 0:
            return
        if graphs.ACTIVE:  # (a read back cannot be part of the caller's capture)
            graphs.refuse_host_read(points.device, "a mesh's check")
        self.clean = False
        device = points.device
        stream = None if device.is_cpu else current_stream(device)
        held = self._check
        if held is None or held[0] is not points or held[1] is not indices or held[2] is not stream:
            check = launch(
                _checked_face_boxes, dim=max(num_points, num_tris), device=device,
                inputs=[points, indices, num_points, num_tris, self.lowers, self.uppers,
                        self.edges, self.found], record_cmd=True,
            ).launch  # fmt: skip
            held = self._check = (points, indices, stream, check)
        if stream is not None and (then or beside):
            self._tail(stream, held[3], then, beside)()  # the check and everything after it
        else:
            held[3]()
            self._read.start()  # the answers only (on a side stream: the rest does not wait)
            self._tail(stream, None, then, beside)()  # (the sum writes nothing when the
            # check found something)
        self._pending = True

    def beside_stream(self) -> Any:
        """The stream ``start``'s ``beside`` launches are prepared on (None on a CPU)."""
        device = self.lowers.device
        return None if device.is_cpu else side_streams(device, 2)[1]

    def _sum_steps(self, stream) -> list:
        """The edge sum's launches prepared on ``stream`` (none without faces)."""
        steps = self._sums.get(stream)
        if steps is None:
            steps = [] if self.lowers.shape[0] == 0 else ChunkSum(
                self.edges, self.edge_sum, guard=self.found, scratch=self._scratch,
                stream=stream).steps  # fmt: skip
            self._sums[stream] = steps
        return steps

    def _tail(self, stream, check: Callable[[], object] | None,
              then: Sequence[Callable[[], object]],
              beside: Sequence[Callable[[], object]]) -> Callable[[], None]:  # fmt: skip
        """What ``start`` runs: the check (unless None: issued already, with the read
        back), then the sum, ``then`` and ``beside`` (see ``start``); the one made before
        for the same launches and stream (the last two are kept: a construction's and a
        refit's), else a new one."""
        for t in self._tails:
            if (t[2] is stream and t[4] is check and _same_steps(t[0], then)
                    and _same_steps(t[1], beside)):  # fmt: skip
                return t[3]
        graphed = graphs_on(self.lowers.device)
        if check is None:  # the sum on the stream, then ``then`` and ``beside``
            run = ForkedSteps([*self._sum_steps(stream), *then, *beside], [], stream, graphed)
        else:
            side, other = side_streams(stream.device, 2)
            read = functools.partial(self._read.copy_on, side)
            run = ForkedSteps(then, [(side, [read, *self._sum_steps(side)]), (other, beside)],
                              stream, graphed, head=[check])  # fmt: skip
        self._tails = [*self._tails[-1:], (tuple(then), tuple(beside), stream, run, check)]
        return run

    def finish(self) -> tuple[int, int]:
        """Wait for the answers of the last ``start``: (the position of the first index
        outside ``[0, points)``, the index of the first point with a NaN or infinite
        coordinate), each -1 when there is none; with one, the boxes are not meaningful
        and ``edge_sum`` is left as it was."""
        if not self._pending:
            return -1, -1
        self._pending = False
        bad_index, bad_point = self._read.values()
        if bad_index or bad_point:
            self.found.zero_()  # "nothing found" again, for the next call
        self.clean = True
        return (
            -1 if bad_index == 0 else _TOP - bad_index,
            -1 if bad_point == 0 else _TOP - bad_point,
        )

    def write(self, points: array, indices: array) -> tuple[int, int]:
        """``start`` then ``finish``: check the mesh and write its faces' boxes, edge
        lengths and edge sum; returns ``finish``'s answer."""
        self.start(points, indices)
        return self.finish()


def _same_steps(a: Sequence, b: Sequence) -> bool:
    return len(a) == len(b) and all(x is y for x, y in zip(a, b))


#: The face boxes of collected meshes, for the next mesh of as many faces (``recycle``:
#: the mesh's BVH build, filed under these boxes, then comes back with them).
FACE_BOXES = RecycleBin(2)


def face_boxes(num_tris: int, device) -> FaceBoxes:
    """``FaceBoxes`` for a mesh of ``num_tris`` faces on ``device``: those of a collected
    mesh when the bin has them, else new ones (``keep_face_boxes`` files them)."""
    boxes = FACE_BOXES.take((), (num_tris, device.alias))
    return boxes if boxes is not None else FaceBoxes(num_tris, device)


def keep_face_boxes(owner: object, boxes: FaceBoxes) -> None:
    """File ``boxes`` in the bin when ``owner`` is collected: the mesh's BVH, which
    reads them as its items (and outlives the mesh when the user keeps it)."""
    shape = (boxes.lowers.shape[0], boxes.lowers.device.alias)
    FACE_BOXES.keep_when_collected(owner, (), shape, boxes, lambda b: b.clean)
