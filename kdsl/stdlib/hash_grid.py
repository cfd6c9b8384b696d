"""kdsl standard library: hash grid queries (Warp's ``hash_grid_query*``), in kdsl.

A ``kdsl.HashGrid`` buckets points into cubic cells of width ``radius`` (the build's
radius): point ``p`` lies in cell ``floor(p / radius)`` per axis, and the cell
coordinates wrap into the grid's ``dim_x * dim_y * dim_z`` cells (so far-apart
cells share a bucket, as in any spatial hash). Kernels reach a grid through its
record (``HashGridRecord``, read with ``object_record``):

- ``point_ids[k]`` is the original index of the ``k``-th point in cell order (points
  sorted by bucket, stably, so a bucket's points keep their original order);
- bucket ``c``'s points are ``point_ids[cell_starts[c] : cell_ends[c]]`` (an empty
  bucket's start equals its end: both 0, or its place in the order, by the build);
- ``num_points`` is 0 until the grid is built.

Since the points are sorted by bucket, the points of consecutive buckets are one
consecutive range of ``point_ids``: a query walks each row of its cell box (the cells
of one ``y`` and ``z``) as one range, or two where the row wraps past the grid's last
``x`` bucket, instead of cell by cell (9 ranges, not 27, for a box of 27 cells). Empty
buckets drop out: a run's range ends at its buckets' largest end and holds the sum of
their counts.

A query visits the buckets of the cells the box ``[point - max_dist, point +
max_dist]`` overlaps (27 cells when ``max_dist`` is the build's radius, at most the
grid's dims per axis, so no bucket is visited twice along an axis), x fastest, then
y, then z, and reports *every* point in them: neighbours are candidates, not
filtered by distance (Warp's contract: the caller tests the distance).
"""

import kdsl as wp
from kdsl.frontend.inout import inout
from kdsl.frontend.kernel import func

__kdsl_group__ = "geometry"

__all__ = ["HashGridQuery", "hash_grid_point_id", "hash_grid_query", "hash_grid_query_next"]

#: Cell coordinates are clamped to int32 as Warp's are: above to ``INT_MAX - 1`` (so a
#: query's ``x + 1`` cannot overflow), below to ``INT_MIN``.
_COORD_MAX = 2147483646
_COORD_MIN = -2147483648


@wp.struct
class HashGridRecord:
    """The record of a ``kdsl.HashGrid`` (see the module docstring)."""

    tag: wp.uint64
    point_ids: wp.array(dtype=wp.int32)
    cell_starts: wp.array(dtype=wp.int32)
    cell_ends: wp.array(dtype=wp.int32)
    dim_x: wp.int32
    dim_y: wp.int32
    dim_z: wp.int32
    num_points: wp.int32
    cell_width_inv: wp.float32


@wp.struct
class HashGridQuery:
    """A query in progress against a ``kdsl.HashGrid`` (Warp's ``hash_grid_query_t``):
    the cell box ``[start, end]`` per axis, the row being visited (``y``, ``z``), the
    first cell of that row not yet visited (``x``), and the range of ``point_ids``
    still to report from the run of buckets before it."""

    grid: wp.uint64
    x_start: wp.int32
    y_start: wp.int32
    z_start: wp.int32
    x_end: wp.int32
    y_end: wp.int32
    z_end: wp.int32
    x: wp.int32
    y: wp.int32
    z: wp.int32
    cell_index: wp.int32
    cell_end: wp.int32


@func
def hash_grid_cell_coord(v: float) -> int:
    """The cell coordinate of ``v`` (a position times the inverse cell width): its floor,
    clamped to int32 (NaN gives 0). The build and the queries share it."""
    c = wp.floor(v)
    if c >= 2147483648.0:
        return _COORD_MAX
    if c >= -2147483648.0:
        return int(c)
    if c < -2147483648.0:
        return _COORD_MIN
    return 0


@func
def _wrap(c: int, dim: int) -> int:
    """``c`` mod ``dim``, in ``[0, dim)``, without an integer division (on a CPU one costs
    more than the rest of a build's key or of a query's step to its next run)."""
    if c >= 0:
        if c < dim:
            return c
    elif c >= -dim:
        return c + dim
    # Farther cells: the quotient through a float64 product with ``1 / dim`` (hoisted out
    # of the thread loop by the compilers), then one step of correction for its rounding.
    q = wp.int64(wp.floor(wp.float64(c) * (wp.float64(1.0) / wp.float64(dim))))
    w = wp.int64(c) - q * wp.int64(dim)
    if w < wp.int64(0):
        w = w + wp.int64(dim)
    elif w >= wp.int64(dim):
        w = w - wp.int64(dim)
    return int(w)


@func
def hash_grid_cell(x: int, y: int, z: int, dim_x: int, dim_y: int, dim_z: int) -> int:
    """The bucket of cell ``(x, y, z)``: each coordinate wrapped into its dim, x fastest."""
    return (_wrap(z, dim_z) * dim_y + _wrap(y, dim_y)) * dim_x + _wrap(x, dim_x)


@func
def _query_end(start: int, end: int, dim: int) -> int:
    """The last cell visited on an axis: ``end``, or ``start + dim - 1`` when the range
    spans the whole axis (its buckets would repeat)."""
    if wp.int64(end) - wp.int64(start) >= wp.int64(dim):
        return start + (dim - 1)
    return end


@func
def _enter_run(query: inout(HashGridQuery), rec: HashGridRecord):
    """Point ``query`` at the points of the run of consecutive buckets that starts at cell
    ``query.x`` of its row: up to the row's last cell or the grid's last ``x`` bucket,
    whichever comes first; ``query.x`` moves past the run."""
    xw = _wrap(query.x, rec.dim_x)
    cells = wp.min(query.x_end - query.x + 1, rec.dim_x - xw)
    c = (_wrap(query.z, rec.dim_z) * rec.dim_y + _wrap(query.y, rec.dim_y)) * rec.dim_x + xw
    hi = 0
    count = 0
    for j in range(cells):
        e = rec.cell_ends[c + j]
        count = count + (e - rec.cell_starts[c + j])
        hi = wp.max(hi, e)
    query.cell_index = hi - count
    query.cell_end = hi
    query.x = query.x + cells


@func
def hash_grid_query(id: wp.uint64, point: wp.vec3, max_dist: float) -> HashGridQuery:
    """A query for the candidate neighbours of ``point``: every point in the cells the box
    ``[point - max_dist, point + max_dist]`` overlaps (not filtered by distance: test it
    yourself). Advance it with ``hash_grid_query_next``."""
    rec = wp.object_record(id, HashGridRecord)
    inv = rec.cell_width_inv
    q = HashGridQuery()
    q.grid = id
    q.x_start = hash_grid_cell_coord((point[0] - max_dist) * inv)
    q.y_start = hash_grid_cell_coord((point[1] - max_dist) * inv)
    q.z_start = hash_grid_cell_coord((point[2] - max_dist) * inv)
    q.x_end = _query_end(q.x_start, hash_grid_cell_coord((point[0] + max_dist) * inv), rec.dim_x)
    q.y_end = _query_end(q.y_start, hash_grid_cell_coord((point[1] + max_dist) * inv), rec.dim_y)
    q.z_end = _query_end(q.z_start, hash_grid_cell_coord((point[2] + max_dist) * inv), rec.dim_z)
    q.x = q.x_start
    q.y = q.y_start
    q.z = q.z_start
    # The cell tables exist from the grid's making and hold only empty buckets until a
    # build: an unbuilt grid's runs are all empty, with no test of its point count.
    _enter_run(q, rec)
    return q


@func
def _next_run(query: inout(HashGridQuery), rec: HashGridRecord) -> bool:
    """Move ``query`` to its next run of buckets (the rest of its row, or the next row's
    first run); False when its box has no more."""
    if query.x > query.x_end:  # the row is done: the next one
        query.x = query.x_start
        query.y = query.y + 1
        if query.y > query.y_end:
            query.y = query.y_start
            query.z = query.z + 1
            if query.z > query.z_end:
                return False
    _enter_run(query, rec)
    return True


@func
def hash_grid_query_next(query: inout(HashGridQuery), index: inout(wp.int32)) -> bool:
    """Advance ``query`` to its next candidate: writes the point's original index to
    ``index`` and gives True, or gives False (``index`` unchanged) when none is left, or
    when the grid has not been built."""
    rec = wp.object_record(query.grid, HashGridRecord)
    found = True
    while found and query.cell_index >= query.cell_end:
        found = _next_run(query, rec)
    if found:
        index = rec.point_ids[query.cell_index]  # noqa: F841 - in-out
        query.cell_index = query.cell_index + 1
    return found


@func
def hash_grid_point_id(id: wp.uint64, index: int) -> int:
    """The original index of the point at position ``index`` of the grid's cell-sorted
    order (launch over the points and read them in this order for locality), or -1 when
    the grid has not been built or ``index`` is outside ``[0, number of points)``."""
    rec = wp.object_record(id, HashGridRecord)
    if index < 0 or index >= rec.num_points:
        return -1
    return rec.point_ids[index]
